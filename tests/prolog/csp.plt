/*  Tests of prolog/csp.pl: network consistency (Figs. 15-17) and AC-3.

    swipl -g run_tests -t halt tests/prolog/csp.plt
*/
:- use_module('../../prolog/spar').
:- use_module('../../prolog/csp').
:- use_module(library(plunit)).
:- use_module(library(assoc)).

:- begin_tests(csp_fig15).

%   Fig. 15: V1 in {1,2,3}, V2 in {2,3,4}, V3 in {4,5,6};
%   C12: V1 + V2 < 5, C23: V2 + V3 < 7, C13: V1 + V3 < 7.

fig15(net(Nodes, Arcs)) :-
    list_to_assoc([v1-[1,2,3], v2-[2,3,4], v3-[4,5,6]], Nodes),
    pairs(v1, v2, 5, P12),
    pairs(v2, v3, 7, P23),
    pairs(v1, v3, 7, P13),
    list_to_assoc([v1-v2-P12, v2-v3-P23, v1-v3-P13], Arcs).

pairs(X, Y, Limit, Pairs) :-
    fig15_labels(X, Lx),
    fig15_labels(Y, Ly),
    findall(A/B, ( member(A, Lx), member(B, Ly), A + B < Limit ), Pairs0),
    sort(Pairs0, Pairs).

fig15_labels(v1, [1,2,3]).
fig15_labels(v2, [2,3,4]).
fig15_labels(v3, [4,5,6]).

test(fig15_two_solutions, Ss == [[v1-1, v2-2, v3-4], [v1-2, v2-2, v3-4]]) :-
    fig15(Net),
    findall(S, solution(Net, S), Ss0),
    msort(Ss0, Ss).

test(fig15_consistent) :-
    fig15(Net),
    consistent(Net).

test(fig17_csp, R == [v3/4, v2/2, v1/1]) :-
    fig15(Net),
    once(csp([v1, v2, v3], Net, R)).

test(fig17_choose_one, Ls == [2]) :-
    fig15(Net),
    findall(L, choose_one(v2, Net, [v1/2], L), Ls).

test(fig17_all_consistent_fails, fail) :-
    fig15(Net),
    all_consistent(v3/6, [v1/1], Net).

test(constraint_pairs_flipped, Pairs == [4/1, 4/2]) :-
    fig15(Net),
    get_constraint_pairs(v3, v1, Pairs0, Net),
    include([A/_]>>(A == 4), Pairs0, Pairs).

test(fig15_ac3, L == [v1-[1,2], v2-[2], v3-[4]]) :-
    fig15(Net),
    ac3(Net, Nodes),
    assoc_to_list(Nodes, L).

test(inconsistent, fail) :-
    list_to_assoc([a-[1], b-[2]], Nodes),
    list_to_assoc([a-b-[1/3]], Arcs),
    consistent(net(Nodes, Arcs)).

test(ac3_wipeout, fail) :-
    list_to_assoc([a-[1], b-[2]], Nodes),
    list_to_assoc([a-b-[1/3]], Arcs),
    ac3(net(Nodes, Arcs), _).

%   solution/3 gives exactly the solutions of solution/2 whose labels its
%   hook keeps, in the order it gives the labels.

no_v1_2(v1, Ls, _, Out) :- !, exclude(==(2), Ls, Out).
no_v1_2(_, Ls, _, Ls).

test(solutions_filtered, Got == Want) :-
    fig15(Net),
    findall(S, solution(Net, no_v1_2, S), Got),
    findall(S, ( solution(Net, S), \+ memberchk(v1-2, S) ), Want),
    findall(S, solution(Net, S), All),
    length(All, NA), length(Want, NW), NW < NA.

test(solutions_reordered, Got == [[v1-2, v2-2, v3-4], [v1-1, v2-2, v3-4]]) :-
    fig15(Net),
    findall(S, solution(Net, [_, Ls, _, Rs]>>reverse(Ls, Rs), S), Got).

%   The hook sees the labels assigned so far: v3 is chosen after v1 and v2
%   (first-fail order), and its hook refuses a label when v1 is 2.

v3_not_with_v1_2(v3, Ls, Assigned, Out) :- !,
    (   get_assoc(v1, Assigned, 2) -> Out = [] ; Out = Ls ).
v3_not_with_v1_2(_, Ls, _, Ls).

%   solution/4 searches the variables in the order its hook gives: v3
%   first, it sees nothing assigned and refuses nothing.

test(solutions_in_given_order, Got == All) :-
    fig15(Net),
    findall(S, solution(Net, [Vs0, [v3|Vs]]>>exclude(==(v3), Vs0, Vs), v3_not_with_v1_2, S), Got),
    findall(S, solution(Net, S), All).

test(solutions_see_assigned, Got == [[v1-1, v2-2, v3-4]]) :-
    fig15(Net),
    findall(S, solution(Net, v3_not_with_v1_2, S), Got).

:- end_tests(csp_fig15).
