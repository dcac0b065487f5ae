;;; Broken on purpose: a copy of domains/ldhp.pddl with one more AdjustGrasp action,
;;; juggle, that no Python implementation is registered for. Loading it passes; the
;;; registry check before any search must raise DomainError naming juggle.
(define (domain ldhp-no-implementation)
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

  ;; juggle: declared here, implemented nowhere.
  (:action juggle
    :parameters ()
    :precondition (touching)
    :effect (and (touching)))
)
