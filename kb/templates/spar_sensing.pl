/*  spar-py: sensing, verification and recovery templates (Sec. 4.3,
    Figs. 11-13), as data for phase 2.

    Phase 1 does not use these; phase 2 (prolog/uncertainty.pl) reads them
    when an uncertainty-reduction goal of a plan instance is not met:

      remedy_rule/3        Sec. 4.3: what to insert into the plan instance,
                           and where, when an action's uncertainty-reduction
                           preconditions fail, in the order tried
      sensing_rule/5       Fig. 11: the dense_range_scan sensing action, the
                           uncertainty variables it introduces, their bounds
                           and the error transformation it leaves
      sensing_units/2      the units of sensing_rule/5's bounds (in, deg)
      verification_template/2  Fig. 12: the sensory verification of an action
      recovery_template/2      Fig. 13: the local recovery plan of an action

    Uncertainty variables are Prolog variables in the templates; phase 2
    reads each sensing rule's variables by their place in its error
    transformation (Dx, Dy, Dz in its displacement row, Theta in its
    rotation about z) and sends their bounds to Python, which gives them
    unique symbols (as Fig. 11's "Generate unique symbols for Theta, Dx, Dy,
    Dz, ActionId, and Gid") each time the sensing action is executed. The
    bounds are those of Fig. 11, in the units sensing_units/2 states (in,
    deg; Python converts them to the cell's units); a problem file's
    sensors.dense_range_scan entry takes precedence where it has one.
*/
:- module(spar_sensing,
          [ remedy_rule/3,             % ?Failing, -Where, -Inserted
            sensing_rule/5,            % ?Sensing, -Vars, -Bounds, -ErrTm, -Template
            sensing_units/2,           % -Length, -Angle
            verification_template/2,   % ?Action, -Verification
            recovery_template/2        % ?Action, -Recovery
          ]).

%!  remedy_rule(?Failing, -Where, -Inserted) is nondet.
%
%   Sec. 4.3: when the uncertainty-reduction preconditions of the action
%   Failing are not met, insert the actions Inserted (in that order) into
%   the plan instance at Where; the clauses are tried in order, the first
%   that makes Failing's preconditions hold is kept. Where is
%
%     - action: just before Failing itself;
%     - establisher(Condition): just before the last action before Failing
%       whose add list (spar_actions:action_template//2) holds Condition.
%
%   An inserted action is a sensing action (one with a sensing_rule/5) or a
%   squeeze(Object), which reduces uncertainty as a pickup does and must
%   meet a pickup's preconditions (Sec. 4.3): so it serves only the
%   assemble, on the object resting on the table. When no rule helps, phase
%   2 plans for failure (Figs. 12-13).
%
%   ==
%   ?- remedy_rule(pickup(peg, p1G1), Where, Inserted).
%   Where = action, Inserted = [dense_range_scan(peg)].
%   ==

remedy_rule(pickup(Object, _Grasp), action, [dense_range_scan(Object)]).
remedy_rule(assemble(Obj1, Obj2, _, _, _), establisher(holding(Obj1, _)),
            [dense_range_scan(Obj1), dense_range_scan(Obj2)]).
remedy_rule(assemble(Obj1, Obj2, _, _, _), establisher(holding(Obj1, _)),
            [dense_range_scan(Obj1), dense_range_scan(Obj2), squeeze(Obj2)]).

%!  sensing_units(-Length, -Angle) is det.
%
%   The units of the numbers in sensing_rule/5's bounds: inches and
%   degrees, as Fig. 11 writes them.

sensing_units(in, deg).

%!  sensing_rule(?Sensing, -Variables, -Bounds, -ErrTm, -Template) is nondet.
%
%   Fig. 11. Sensing is the sensing action (dense_range_scan(Object));
%   Variables the new uncertainty variables as supinf_variable(V) terms;
%   Bounds their bounds as supinf_less(A, B) terms (A < B); ErrTm the error
%   transformation (the paper's row form tm([R1, R2, R3, D])); Template the
%   sensing action in the shape of an action template (Fig. 5), its id
%   ActionId and goal id Gid unbound.

sensing_rule(dense_range_scan(Object),
             [ supinf_variable(Dx), supinf_variable(Dy),
               supinf_variable(Dz), supinf_variable(Theta) ],
             [ supinf_less(-0.05, Dx), supinf_less(Dx, 0.05),
               supinf_less(-0.05, Dy), supinf_less(Dy, 0.05),
               supinf_less(-0.05, Dz), supinf_less(Dz, 0.05),
               supinf_less(-0.5, Theta), supinf_less(Theta, 0.5) ],
             ErrTm,
             sensing_action(ActionId,
                            dense_range_scan(Object),
                            preconditions([op(_Gid, ActionId, gripper(open))],
                                          []),
                            addlist([part_location_unc(Object, ErrTm)]),
                            dellist([part_location_unc(Object, _)]))) :-
    ErrTm = tm([ [cos(Theta), sin(Theta), 0],
                 [-1*sin(Theta), cos(Theta), 0],
                 [0, 0, 1],
                 [Dx, Dy, Dz] ]).

%!  verification_template(?Action, -Verification) is nondet.
%
%   Fig. 12: the sensory verification of Action. Verification is
%   verification(ActionId, Parameters, ErrorStates): Parameters name the
%   quantities the check compares (Name = Source), ErrorStates are
%   Condition -> ErrorState pairs tried in order.

verification_template(pickup(Object, Grasp),
                      verification(_ActionId,
                                   [ wg = width_of(Object, Grasp),
                                     w = gripper_opening ],
                                   [ (w =:= wg) -> success,
                                     (w =:= 0) -> error1,
                                     true -> error2 ])).

%!  recovery_template(?Action, -Recovery) is nondet.
%
%   Fig. 13: the local recovery plan of Action, recovery(ActionId,
%   ErrorState -> Response pairs).

recovery_template(pickup(_Object, _Grasp),
                  recovery(_ActionId,
                           [ success -> return(true),
                             error1 -> local_grope,
                             error2 -> summon_user ])).

:- discontiguous verification_template/2, recovery_template/2.

%   The paper gives Figs. 12-13 for pickup only. For assemble (peg into
%   hole) we verify by the insertion depth the arm reached against the
%   depth the goal transform implies (a position check along the approach
%   vector), with the same three outcomes; a jammed peg (depth short) gets a
%   local spiral search, anything else the user.

verification_template(assemble(Peg, Hole, _, Ta, Va),
                      verification(_ActionId,
                                   [ dg = insertion_depth(Peg, Hole, Ta),
                                     d = depth_reached_along(Va) ],
                                   [ (d >= dg) -> success,
                                     (d < dg) -> error1,
                                     true -> error2 ])).

recovery_template(assemble(_Peg, _Hole, _, _, _),
                  recovery(_ActionId,
                           [ success -> return(true),
                             error1 -> local_grope,
                             error2 -> summon_user ])).
