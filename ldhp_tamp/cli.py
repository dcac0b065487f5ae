"""The ``ldhp-tamp`` command line. The only place that turns errors into exit codes.

Exit status: 0 solved (or valid), 1 no plan found (or invalid plan), 2 bad input or
usage. Anything else is a bug. Logs go to stderr; results to stdout or files.
"""

from __future__ import annotations

import argparse
import logging
import sys
from typing import Callable, Sequence

from ldhp_tamp.errors import InputError

log = logging.getLogger("ldhp_tamp")

EXIT_OK = 0
EXIT_NO_PLAN = 1
EXIT_BAD_INPUT = 2

EXIT_CODES_HELP = """exit status:
  0  solved (or the plan is valid)
  1  no plan found (or the plan is invalid)
  2  bad input or usage (the message names the file and the problem)
"""


class _Parser(argparse.ArgumentParser):
    """argparse that exits with status 2 and a one-line message on usage errors."""

    def error(self, message: str) -> None:  # pragma: no cover - exercised via CLI tests
        self.print_usage(sys.stderr)
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def cmd_check(args: argparse.Namespace) -> int:
    from ldhp_tamp.scenario import load_scenario, summarize

    status = EXIT_OK
    for path in args.scenarios:
        try:
            scenario = load_scenario(path)
        except InputError as exc:
            print(f"error: {exc}", file=sys.stderr)
            status = EXIT_BAD_INPUT
            continue
        print(summarize(scenario))
    return status


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {"check": cmd_check}


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="ldhp-tamp",
        description="LDHP planner for non-prehensile manipulation with a parallel-jaw gripper.",
        epilog=EXIT_CODES_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output on stderr")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("check", help="load scenarios and print a short summary of each",
                       epilog=EXIT_CODES_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenarios", nargs="+", metavar="SCENARIO", help="scenario TOML files")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.WARNING - 10 * min(args.verbose, 2),
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        return COMMANDS[args.command](args)
    except InputError as exc:
        if args.debug:
            raise
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
