/*  Tests of phase 2's remedies as data: spar_sensing:remedy_rule/3 in the
    order tried (Sec. 4.3), how uncertainty.pl interprets them (where to
    insert, the ids of inserted steps), and Fig. 11's sensing rule read as
    the bounds Python receives.

    swipl -g run_tests -t halt tests/prolog/remedies.plt
*/
:- use_module('../../prolog/uncertainty').
:- use_module(library(plunit)).
:- use_module(library(apply)).
:- use_module(library(lists)).

:- begin_tests(remedies).

test(pickup_gets_a_scan_before_itself, Rules == [action-[dense_range_scan(peg)]]) :-
    findall(W-I, spar_sensing:remedy_rule(pickup(peg, p1G1), W, I), Rules).

test(assemble_scans_then_scans_and_squeeze,
     Rules == [ [dense_range_scan(peg), dense_range_scan(block)],
                [dense_range_scan(peg), dense_range_scan(block), squeeze(block)] ]) :-
    findall(I, spar_sensing:remedy_rule(assemble(peg, block, [[peg_face], [block_face]], trans_1, vec_1),
                                        establisher(holding(peg, _)), I),
            Rules).

test(establisher_of_holding_is_the_last_pickup, At == action_2) :-
    Before = [ step(action_4, pickup(block, p2G1)),
               step(action_3, putdown(block, p2P1)),
               step(sense(action_2, 1), dense_range_scan(peg)),
               step(action_2, pickup(peg, p1G10)) ],
    uncertainty:insertion_point(establisher(holding(peg, _)), action_1, Before, At).

test(no_establisher, fail) :-
    uncertainty:insertion_point(establisher(holding(peg, _)), action_1,
                                [step(action_4, pickup(block, p2G1))], _).

test(inserted_step_ids,
     Steps == [ step(sense(action_1, 1), dense_range_scan(peg)),
                step(sense(action_1, 2), dense_range_scan(block)),
                step(squeeze(action_1), squeeze(block)) ]) :-
    uncertainty:inserted_steps([dense_range_scan(peg), dense_range_scan(block), squeeze(block)],
                               action_1, Steps).

test(unknown_remedy_action, [error(domain_error(remedy_action, wiggle(peg)))]) :-
    uncertainty:inserted_steps([wiggle(peg)], action_1, _).

test(fig11_bounds_as_data,
     Got == [[-0.05, 0.05], [-0.05, 0.05], [-0.05, 0.05], [-0.5, 0.5], in, deg]) :-
    uncertainty:sensing_data(Data),
    get_dict(dense_range_scan, Data, D),
    get_dict(units, D, U),
    maplist(dict_value(D), [dx, dy, dz, dtheta], Bounds),
    get_dict(length, U, L), get_dict(angle, U, A),
    append(Bounds, [L, A], Got).

dict_value(D, K, V) :- get_dict(K, D, V).

test(other_error_transform, [error(domain_error(sensing_error_transform, _))]) :-
    uncertainty:rule_bounds(tm([[1, 0, 0], [0, 1, 0], [0, 0, 1], [X, 0, 0]]),
                            [supinf_variable(X)], [supinf_less(-1, X), supinf_less(X, 1)], _).

:- end_tests(remedies).
