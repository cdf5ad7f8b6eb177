/*  spar-py: action templates and instantiation rules (Sec. 3.1, Figs. 2-6).

    An instantiated template is the term of Fig. 5:

      action(ActionId, Action,
             preconditions(OpGoals, GeoGoals),
             addlist(Adds), dellist(Dels))

    with operational goals op(GoalId, ActionId, Condition) and geometric
    goals geo(GoalId, ActionId, Constraint, OpConditions) (Sec. 3.4; the
    paper writes the operational conditions as trailing arguments, here
    they are one list). The uncertainty-reduction preconditions and the
    part_location_unc/2 elements of the add and delete lists are procedures
    of phase 2 (Sec. 3.1: "they are really not a part of the clause"), so
    they do not appear here.

    The rule base is indexed by the goal an action establishes
    (instantiate_establishing_action//3, Fig. 6). Unique symbols (action_N,
    goal_N, grasp_N, pos_N) come from gensym//2, a stand-in for the gensym/2
    of Fig. 6 whose counters are threaded through the plan state as a list
    Prefix-LastNumber: backtracking over a planner choice takes the numbers
    back, so the same problem always gets the same names (Figs. 21-25).
*/
:- module(spar_actions,
          [ instantiate_establishing_action//3, % +Goal, -Action, -Constraints
            action_template//2,                 % +Action, -Template
            establishes/2,                      % ?Goal, ?ActionName
            gensym//2,                          % +Prefix, -Symbol
            get_all_grasps/2,                   % +Object, -Grasps
            get_all_poses/2,                    % +Object, -Poses
            mating_grasps/3,                    % +Object, +Faces, -Grasps
            mating_grasps/4,                    % +Object, +Faces, +Ta, -Grasps
            mating_poses/3,                     % +Object, +Faces, -Poses
            assembly_turn/3,                    % +Ta, -Turn, -HolePoses
            turn_class/2                        % +Turn, -Ta
          ]).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(error)).
:- use_module(library(yall)).
:- use_module('../../prolog/kb', []).

%!  establishes(?Goal, ?ActionName) is nondet.
%
%   The index of the rule base: an action named ActionName can be added to
%   establish Goal (the add lists of Figs. 2-4). Documentation and
%   introspection; instantiate_establishing_action//3 is the rule base.

establishes(holding(_, _), pickup).
establishes(gripper(closed), pickup).
establishes(part_location(_, _), putdown).
establishes(gripper(open), putdown).
establishes(assembled(_, _, _, _, _), assemble).

%!  instantiate_establishing_action(+Goal, -Action, -Constraints)// is nondet.
%
%   Action is a new instantiated template that establishes Goal and
%   Constraints its initial constraints (Figs. 5-6), which the planner posts
%   without a consistency check when they create a node (Sec. 3.1). The
%   DCG arguments are the symbol counters. Rules:
%
%     - holding(Obj, Grasp): pickup(Obj, Grasp), member(Grasp, all grasps
%       of Obj) (Fig. 6);
%     - part_location(Obj, Pos): putdown(Obj, Pos), Pos in the position
%       class of all stable poses of Obj;
%     - gripper(open): putdown of some held object (tried per object);
%     - gripper(closed): pickup of some object (tried per object);
%     - assembled(Obj1, Obj2, [M1, M2], Ta, Va): assemble, its GraspList the
%       grasps of Obj1 whose ofaces avoid M1 and its PositionList the stable
%       poses of Obj2 whose ofaces avoid M2 (Sec. 6); no initial constraint.
%       A derived Ta (goal assembled(Peg, Hole)) stands for its turns about
%       the hole's axis: the assemble uses one Turn of them, a choice tried
%       in order and taken back on backtracking (assembly_turn/3), and its
%       PositionList keeps only the poses in which the peg so turned clears
%       the table. Its add list gives the goal's Ta (turn_class/2).
%
%   A variable of the goal that is still unbound (Grasp, Pos) gets a new
%   symbol; a bound one is kept, so a new action re-establishes exactly the
%   goal it is for.

instantiate_establishing_action(holding(Object, Grasp), Action, Constraints) -->
    { object_of(Object) },
    new_plan_variable(grasp_, Grasp),
    action_template(pickup(Object, Grasp), Action),
    { get_all_grasps(Object, GraspList),
      Constraints = [member(Grasp, GraspList)] }.
instantiate_establishing_action(part_location(Object, Pos), Action,
                                Constraints) -->
    { object_of(Object) },
    new_plan_variable(pos_, Pos),
    action_template(putdown(Object, Pos), Action),
    { get_all_poses(Object, PoseList),
      Constraints = [in_position_class(Pos, PoseList)] }.
instantiate_establishing_action(gripper(open), Action, Constraints) -->
    instantiate_establishing_action(part_location(_, _), Action, Constraints).
instantiate_establishing_action(gripper(closed), Action, Constraints) -->
    instantiate_establishing_action(holding(_, _), Action, Constraints).
instantiate_establishing_action(assembled(Obj1, Obj2, [M1, M2], Ta, Va),
                                Action, []) -->
    { assembly_turn(Ta, Turn, Clear),
      mating_grasps(Obj1, M1, Ta, GraspList),
      mating_poses(Obj2, M2, Poses),
      clear_poses(Clear, Poses, PositionList),
      PositionList \== [] },
    action_template(assemble(Obj1, Obj2, [M1, M2], Turn, Va), Action),
    { action_geo_goals(Action, Geos),
      memberchk(geo(_, _, member(_, GraspList), _), Geos),
      memberchk(geo(_, _, in_position_class(_, PositionList), _), Geos) }.

%!  assembly_turn(+Ta, -Turn, -HolePoses) is nondet.
%
%   Turn is a transform an assemble for a goal naming Ta may use, and
%   HolePoses the hole part's stable poses it allows (`all`: no limit):
%   the turns of a derived Ta (kb:turn/3) in order, else Ta itself.
%
%   @error instantiation_error if Ta is unbound.

assembly_turn(Ta, Turn, HolePoses) :-
    must_be(atom, Ta),
    (   kb:turn(Ta, _, _)
    ->  kb:turn(Ta, Turn, HolePoses)
    ;   Turn = Ta,
        HolePoses = all
    ).

%!  turn_class(?Turn, -Ta) is det.
%
%   Ta is the transform a goal names whose turn Turn is (Turn itself for a
%   transform that is no derived turn, or an unbound Turn).

turn_class(Turn, Ta) :-
    (   atom(Turn),
        kb:turn(Ta0, Turn, _)
    ->  Ta = Ta0
    ;   Ta = Turn
    ).

%   clear_poses(+Clear, +Poses0, -Poses): the poses of Poses0 that Clear
%   (a list, or `all`) allows. No yall lambda: its free Clear would be
%   renamed in the compiled body.

clear_poses(all, Poses, Poses) :- !.
clear_poses(Clear, Poses0, Poses) :-
    include(in_list(Clear), Poses0, Poses).

in_list(List, X) :-
    memberchk(X, List).

object_of(Object) :-
    (   atom(Object) -> true ; kb:object(Object) ).

new_plan_variable(Prefix, V) -->
    (   { var(V) }
    ->  gensym(Prefix, V)
    ;   []
    ).

action_geo_goals(action(_, _, preconditions(_, Geos), _, _), Geos).

%!  action_template(+Action, -Template)// is det.
%
%   The template of Figs. 2-4 for Action (pickup/2, putdown/2, assemble/5)
%   with a new action id and new goal ids. An assemble with a turn of a
%   derived T_a adds the assembled/5 its goal names, with that T_a
%   (turn_class/2); otherwise its Transform is the goal's.

action_template(pickup(Object, Grasp), Template) -->            % Fig. 2
    gensym(action_, Id),
    gensym(goal_, G1), gensym(goal_, G2), gensym(goal_, G3),
    { Template =
        action(Id, pickup(Object, Grasp),
               preconditions(
                   [ op(G1, Id, gripper(open)),
                     op(G2, Id, part_location(Object, Pos)) ],
                   [ geo(G3, Id, reachable(Grasp, Pos),
                         [part_location(Object, Pos)]) ]),
               addlist([holding(Object, Grasp), gripper(closed)]),
               dellist([part_location(Object, Pos), gripper(open)])) }.
action_template(putdown(Object, Pos), Template) -->             % Fig. 3
    gensym(action_, Id),
    gensym(goal_, G1), gensym(goal_, G2),
    { Template =
        action(Id, putdown(Object, Pos),
               preconditions(
                   [ op(G1, Id, holding(Object, Grasp)) ],
                   [ geo(G2, Id, reachable(Grasp, Pos),
                         [holding(Object, Grasp)]) ]),
               addlist([part_location(Object, Pos), gripper(open)]),
               dellist([gripper(closed), holding(Object, Grasp)])) }.
action_template(assemble(Obj1, Obj2, [M1, M2], Transform, Mvector),   % Fig. 4
                Template) -->
    { turn_class(Transform, Ta) },
    gensym(action_, Id),
    gensym(goal_, G1), gensym(goal_, G2), gensym(goal_, G3),
    gensym(goal_, G4), gensym(goal_, G5),
    { Template =
        action(Id, assemble(Obj1, Obj2, [M1, M2], Transform, Mvector),
               preconditions(
                   [ op(G1, Id, holding(Obj1, Grasp)),
                     op(G2, Id, part_location(Obj2, Pos)) ],
                   [ geo(G3, Id, member(Grasp, _GraspList),
                         [holding(Obj1, Grasp)]),
                     geo(G4, Id, in_position_class(Pos, _PositionList),
                         [part_location(Obj2, Pos)]),
                     geo(G5, Id, mate_reachable(Grasp, Pos, Transform),
                         [holding(Obj1, Grasp), part_location(Obj2, Pos)]) ]),
               addlist([assembled(Obj1, Obj2, [M1, M2], Ta, Mvector),
                        gripper(open)]),
               dellist([gripper(closed), holding(Obj1, Grasp)])) }.

%!  gensym(+Prefix, -Symbol)// is det.
%
%   Symbol is Prefix followed by the next number of Prefix's counter; the
%   DCG arguments are the counters, a list of Prefix-LastNumber.
%
%   ==
%   ?- phrase(gensym(goal_, S), [], C).
%   S = goal_1, C = [goal_-1].
%   ==

gensym(Prefix, Symbol, Counters0, [Prefix-N|Rest]) :-
    must_be(atom, Prefix),
    (   selectchk(Prefix-N0, Counters0, Rest)
    ->  true
    ;   N0 = 0, Rest = Counters0
    ),
    N is N0 + 1,
    atom_concat(Prefix, N, Symbol).

%!  get_all_grasps(+Object, -Grasps:list) is det.
%
%   The labels of all grasping configurations of Object (Fig. 19), in the
%   knowledge base's order.

get_all_grasps(Object, Grasps) :-
    findall(G, kb:grasp(Object, G, _, _, _, _), Grasps).

%!  get_all_poses(+Object, -Poses:list) is det.
%
%   The labels of all stable poses of Object (Fig. 18).

get_all_poses(Object, Poses) :-
    findall(P, kb:pose(Object, P, _, _, _), Poses).

%!  mating_grasps(+Object, +Faces, -Grasps:list) is det.
%
%   The grasps of Object that obscure none of Faces (its mating features).

mating_grasps(Object, Faces, Grasps) :-
    findall(G, ( kb:grasp(Object, G, _, ofaces(Os), _, _),
                 disjoint(Os, Faces) ),
            Grasps).

%!  mating_grasps(+Object, +Faces, +Ta, -Grasps:list) is det.
%
%   The grasps of Object usable for an assemble seating it at Ta: those
%   the geometry allows (kb:mate_grasps/3, written where the goal's
%   features have an axis and a length: the hand holds only what stays
%   out of the hole), else those obscuring none of Faces (mating_grasps/3).
%
%   @error instantiation_error if Object or Ta is unbound.

mating_grasps(Object, Faces, Ta, Grasps) :-
    must_be(atom, Object),
    must_be(atom, Ta),
    (   kb:mate_grasps(Ta, Object, Gs)
    ->  Grasps = Gs
    ;   mating_grasps(Object, Faces, Grasps)
    ).

%!  mating_poses(+Object, +Faces, -Poses:list) is det.
%
%   The stable poses of Object that obscure none of Faces (Sec. 6: "stable
%   poses which do not obscure any of its mating features").

mating_poses(Object, Faces, Poses) :-
    findall(P, ( kb:pose(Object, P, _, ofaces(Os), _),
                 disjoint(Os, Faces) ),
            Poses).

disjoint(Xs, Ys) :-
    \+ ( member(X, Xs), memberchk(X, Ys) ).
