/*  Tests of uncertainty:instance_sources/2: which part of a stock each
    action of a plan instance takes (phase 2 needs it when an object has
    several initial positions; kb/problems/separation.yaml).

    swipl -g run_tests -t halt tests/prolog/sources.plt
*/
:- use_module('../../prolog/uncertainty').
:- use_module(library(plunit)).

:- begin_tests(instance_sources).

%   An instance as spar:partial_instances/2 gives it: network variables
%   replaced by their labels (init_pos5 by tr5, init_pos2 by tr2).

instance(instance(
    [ action(action_2, pickup(peg, p1G10),
             preconditions([ op(goal_6, action_2, gripper(open)),
                             op(goal_7, action_2, part_location(peg, tr5)) ],
                           [ geo(goal_8, action_2, reachable(p1G10, tr5),
                                 [part_location(peg, tr5)]) ]),
             addlist([holding(peg, p1G10), gripper(closed)]),
             dellist([part_location(peg, tr5), gripper(open)])),
      action(action_1, assemble(peg, block, [[peg_face], [block_face]], trans_1, vec_1),
             preconditions([ op(goal_1, action_1, holding(peg, p1G10)),
                             op(goal_2, action_1, part_location(block, tr2)) ],
                           []),
             addlist([]), dellist([])),
      action(action_3, putdown(peg, p1P1),
             preconditions([ op(goal_9, action_3, holding(peg, p1G10)) ], []),
             addlist([]), dellist([]))
    ],
    [grasp_1 = p1G10])).

test(pickup_and_assemble_sources,
     Sources == [action_2-[peg-tr5], action_1-[block-tr2]]) :-
    instance(I),
    instance_sources(I, Sources).

test(steps_unchanged, Ids == [action_2, action_1, action_3]) :-
    instance(I),
    instance_steps(I, Steps, _),
    findall(Id, member(step(Id, _), Steps), Ids).

:- end_tests(instance_sources).
