/*  Tests of kb/templates/spar_actions.pl (Figs. 2-6) and spar_sensing.pl
    (Figs. 11-13).

    swipl -g run_tests -t halt tests/prolog/templates.plt
*/
:- use_module('../../prolog/spar').
:- use_module(spar(kb/templates/spar_actions)).
:- use_module(spar(kb/templates/spar_sensing)).
:- use_module(fixtures/paper_cell).
:- use_module(library(plunit)).

:- begin_tests(templates_figs2_6, [setup(load_cell(hole_down))]).

test(gensym_threaded, Syms-C == [goal_1, goal_2, action_1]-[action_-1, goal_-2]) :-
    phrase(( gensym(goal_, A), gensym(goal_, B), gensym(action_, D) ), [], C0),
    Syms = [A, B, D],
    msort(C0, C).

test(gensym_continues, S == goal_8) :-
    phrase(gensym(goal_, S), [goal_-7], _).

test(fig6_pickup_rule,
     [ Action-Cs =@= action(action_1, pickup(peg, grasp_1),
                           preconditions([ op(goal_1, action_1, gripper(open)),
                                           op(goal_2, action_1, part_location(peg, P)) ],
                                         [ geo(goal_3, action_1, reachable(grasp_1, P),
                                               [part_location(peg, P)]) ]),
                           addlist([holding(peg, grasp_1), gripper(closed)]),
                           dellist([part_location(peg, P), gripper(open)]))
                    -[member(grasp_1, Gs)] ]) :-
    phrase(instantiate_establishing_action(holding(peg, _), Action, Cs), [], _),
    get_all_grasps(peg, Gs).

test(fig3_putdown_rule, T-Cs == putdown(block, pos_1)-[in_position_class(pos_1, [p2P1, p2P2, p2P3, p2P4, p2P5, p2P6])]) :-
    phrase(instantiate_establishing_action(part_location(block, _),
                                           action(_, T, _, _, _), Cs), [], _).

test(bound_variable_kept, T == putdown(block, init_pos2)) :-
    phrase(instantiate_establishing_action(part_location(block, init_pos2),
                                           action(_, T, _, _, _), _), [], _).

test(gripper_open_by_putdown, Ts == [putdown(peg, pos_1), putdown(block, pos_1)]) :-
    findall(T, phrase(instantiate_establishing_action(gripper(open),
                                                      action(_, T, _, _, _), _), [], _),
            Ts).

test(sec6_assemble_lists, [Ns-PL == 14-[p2P1, p2P2, p2P4, p2P5, p2P6]]) :-
    phrase(instantiate_establishing_action(
               assembled(peg, block, [[peg_face], [block_face]], trans_1, vec_1),
               action(action_1, _, preconditions(_, Geos), _, _), []), [], _),
    Geos = [ geo(goal_3, action_1, member(_, GL), _),
             geo(goal_4, action_1, in_position_class(_, PL), _),
             geo(goal_5, action_1, mate_reachable(_, _, trans_1), [_, _]) ],
    length(GL, Ns).

test(mating_grasps_by_ofaces, Gs4 == Gs3) :-
    % no kb:mate_grasps/3 for the paper's goal (its features have no geometry): the ofaces rule
    mating_grasps(peg, [peg_face], Gs3),
    mating_grasps(peg, [peg_face], trans_1, Gs4),
    length(Gs3, 14).

test(mating_grasps_unbound_ta, [error(instantiation_error)]) :-
    mating_grasps(peg, [peg_face], _, _).

test(no_rule, fail) :-
    phrase(instantiate_establishing_action(glued(peg, block), _, _), [], _).

test(index, As == [assemble, pickup, pickup, putdown, putdown]) :-
    findall(A, establishes(_, A), As0),
    msort(As0, As).

:- end_tests(templates_figs2_6).

%   The paper's cell with trans_1 as a derived T_a of two turns: the first
%   allows the block's poses p2P1 and p2P2, the second (trans_1_t2) p2P4.
load_turn_cell :-
    cell_facts(hole_down, Facts0),
    append(Facts0, [ transform(trans_1_t2, tm([[-1,0,0],[0,1,0],[0,0,-1],[0,0,2.5]])),
                     turn(trans_1, trans_1, [p2P1, p2P2]),
                     turn(trans_1, trans_1_t2, [p2P4]) ], Facts),
    kb:replace_facts(Facts).

:- begin_tests(templates_turns, [setup(load_turn_cell), cleanup(load_cell(hole_down))]).

test(turns_in_order, Ts == [trans_1-[p2P1, p2P2], trans_1_t2-[p2P4]]) :-
    findall(T-H, assembly_turn(trans_1, T, H), Ts).

test(plain_transform_is_its_own_turn, Ts == [trans_9-all]) :-
    findall(T-H, assembly_turn(trans_9, T, H), Ts).

test(unbound_ta, [error(instantiation_error)]) :-
    assembly_turn(_, _, _).

test(turn_class, Cs == [trans_1, trans_1, trans_9]) :-
    maplist(turn_class, [trans_1, trans_1_t2, trans_9], Cs).

test(assemble_per_turn, Alts == [trans_1-[p2P1, p2P2], trans_1_t2-[p2P4]]) :-
    Goal = assembled(peg, block, [[peg_face], [block_face]], trans_1, vec_1),
    findall(T-PL, ( phrase(instantiate_establishing_action(Goal, Action, []), [], _),
                    Action = action(_, assemble(_, _, _, T, _), preconditions(_, Geos),
                                    addlist(Adds), _),
                    memberchk(Goal, Adds),
                    memberchk(geo(_, _, in_position_class(_, PL), _), Geos),
                    memberchk(geo(_, _, mate_reachable(_, _, T), _), Geos) ),
            Alts).

:- end_tests(templates_turns).

:- begin_tests(templates_figs11_13).

test(fig11_dense_range_scan, [Vs-NB == 4-8]) :-
    sensing_rule(dense_range_scan(peg), Vars, Bounds, tm([_, _, _, [Dx, _, _]]),
                 sensing_action(_, dense_range_scan(peg), _,
                                addlist([part_location_unc(peg, _)]), _)),
    memberchk(supinf_variable(V), Vars), V == Dx,
    length(Vars, Vs),
    length(Bounds, NB).

test(fig12_verification, States == [success, error1, error2]) :-
    verification_template(pickup(peg, grasp_1), verification(_, _, Pairs)),
    findall(S, member(_ -> S, Pairs), States).

test(fig13_recovery, R == [return(true), local_grope, summon_user]) :-
    recovery_template(pickup(peg, grasp_1), recovery(_, Pairs)),
    findall(X, member(_ -> X, Pairs), R).

:- end_tests(templates_figs11_13).
