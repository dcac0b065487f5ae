;;; ===========================================================================
;;; ldhp.pddl -- the primitive library of LDHP as a PDDL domain
;;; ===========================================================================
;;;
;;; This file IS the primitive library (paper, "Primitive Library"). Each action
;;; is one primitive, bound by its name to a Python implementation in
;;; ldhp_tamp.primitives (see docs/extending.md). Deleting an action removes
;;; the primitive from BOTH tiers of the planner:
;;;   - top tier: the contact-state plan can no longer use it;
;;;   - bottom tier: the grasp graph only builds intra-pose edges from the
;;;     AdjustGrasp actions declared here.
;;;
;;; Families are read from the actions themselves, not from a list:
;;;   MoveObject   (tip, push, biplanar-slide, air-move): an action whose
;;;                effect changes (at ?s) -- it moves the object to another
;;;                contact state while the grasp is kept;
;;;   AdjustGrasp  (open, close, pivot, slide, flip, approach-contact): every
;;;                other action -- it changes the grasp at a fixed object pose.
;;;
;;; Conventions the planner checks when it loads a domain
;;; (ldhp_tamp.symbolic.load_domain):
;;;   1. The problem vocabulary exists: (at ?s - state), (touching), (hand-free).
;;;   2. A MoveObject action <a> has the static precondition (can-<a> ?from ?to)
;;;      over two `state` parameters: the transition from ?from to ?to is
;;;      admissible for <a>. The geometric backend (the implementation's
;;;      transitions()) computes the admissible pairs and the problem builder
;;;      writes them as facts; no action may add or delete a can-* fact.
;;;
;;; Requirements: plain STRIPS with typing and NO negative preconditions and
;;; NO action costs, so that every engine -- pyperplan included -- solves it
;;; exactly as written. (A domain that declares action costs is refused by
;;; engines that would silently ignore them.)
;;;
;;; What the problem builder writes (ldhp_tamp.symbolic.build_problem):
;;;   objects   one `state` object per contact state: s-free, s-l1-e1,
;;;             s-v2-e1_l3-e4 (contacts joined by "_"), ...
;;;   init      (at <start>); (touching) if the object starts held, else
;;;             (hand-free); (can-<a> <from> <to>) for every admissible
;;;             transition of every MoveObject action that the TAMP loop has
;;;             not forbidden yet.
;;;   goal      (at <goal>), plus (hand-free) when the task asks the gripper
;;;             to release the object at the end (goal_release).
;;; ===========================================================================

(define (domain ldhp)
  (:requirements :strips :typing)

  (:types
    state  ; a contact state: the set of object-environment principal contacts
  )

  (:predicates
    ;; --- fluents -------------------------------------------------------------
    (at ?s - state)    ; the object is in contact state ?s (exactly one holds)
    (touching)         ; some finger touches the object (a grasp is engaged)
    (hand-free)        ; no finger touches the object; the complement of
                       ; (touching), kept as its own predicate because STRIPS
                       ; engines such as pyperplan have no negative preconditions

    ;; --- static admissibility, one per MoveObject action ----------------------
    ;; (can-<a> ?from ?to): primitive <a> can take the object from ?from to ?to.
    ;; Written by the problem builder from the geometric backend; never changed
    ;; by an action.
    (can-tip ?from ?to - state)
    (can-push ?from ?to - state)
    (can-biplanar-slide ?from ?to - state)
    (can-air-move ?from ?to - state)
  )

  ;; ==========================================================================
  ;; MoveObject: change the contact state, keep the grasp.
  ;; All four need a finger on the object: the gripper is what moves it.
  ;; ==========================================================================

  ;; tip: rotate the object about a sticking/rolling contact on an environment
  ;; edge (e.g. l1-e1 -> v2-e1). Contact-sensitive: the bottom tier may bisect it.
  (:action tip
    :parameters (?from ?to - state)
    :precondition (and (at ?from) (touching) (can-tip ?from ?to))
    :effect (and (not (at ?from)) (at ?to)))

  ;; push: translate along one environment edge keeping contact (the contact
  ;; state may change when a vertex reaches the end of the edge).
  (:action push
    :parameters (?from ?to - state)
    :precondition (and (at ?from) (touching) (can-push ?from ?to))
    :effect (and (not (at ?from)) (at ?to)))

  ;; biplanar-slide: slide on two environment edges at once (corner guidance),
  ;; coupling translation and rotation. Contact-sensitive, like tip.
  (:action biplanar-slide
    :parameters (?from ?to - state)
    :precondition (and (at ?from) (touching) (can-biplanar-slide ?from ?to))
    :effect (and (not (at ?from)) (at ?to)))

  ;; air-move: free-space motion; the transitions between s-free and a contact
  ;; state (leave or reach the environment) are admitted by can-air-move.
  (:action air-move
    :parameters (?from ?to - state)
    :precondition (and (at ?from) (touching) (can-air-move ?from ?to))
    :effect (and (not (at ?from)) (at ?to)))

  ;; ==========================================================================
  ;; AdjustGrasp: change the grasp at a fixed object pose.
  ;; Symbolically only (touching)/(hand-free) is tracked; which grasp, which
  ;; finger, which edge is the bottom tier's business (the grasp graph uses
  ;; exactly the AdjustGrasp actions declared in this file).
  ;; ==========================================================================

  ;; approach-contact: bring the fingers from free space onto the object.
  ;; The ONLY action that makes (touching) true: without it, a task whose
  ;; object starts without contact has no plan (MoveObject needs touching).
  (:action approach-contact
    :parameters ()
    :precondition (hand-free)
    :effect (and (touching) (not (hand-free))))

  ;; open: widen the gripper until no finger touches the object.
  ;; The ONLY action that makes (hand-free) true: without it, a task with
  ;; goal_release has no plan.
  (:action open
    :parameters ()
    :precondition (touching)
    :effect (and (hand-free) (not (touching))))

  ;; close, pivot, slide, flip keep the object touched. They never change the
  ;; symbolic state, so a symbolic plan never contains them; they are declared
  ;; here so that the bottom tier may use them (and so that deleting one
  ;; removes it from the grasp graph).

  ;; close: narrow the gripper to engage a second finger.
  (:action close
    :parameters ()
    :precondition (touching)
    :effect (and (touching)))

  ;; pivot: rotate the gripper about a contacting finger.
  (:action pivot
    :parameters ()
    :precondition (touching)
    :effect (and (touching)))

  ;; slide: slide a contacting finger along an object edge.
  (:action slide
    :parameters ()
    :precondition (touching)
    :effect (and (touching)))

  ;; flip: rotate the gripper 180 degrees about its axis to switch facing.
  (:action flip
    :parameters ()
    :precondition (touching)
    :effect (and (touching)))
)
