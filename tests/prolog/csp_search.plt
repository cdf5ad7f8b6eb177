/*  csp/3 looks a label up only against the assigned variables it shares an
    arc with (a table of arcs per variable, reversed arcs tested as L1/Label);
    Fig. 17 as written (choose_one/4, all_consistent/3) checks every previous
    assignment. Both must give the same solutions in the same order, arcs
    stored in either orientation or in both.

    swipl -g run_tests -t halt tests/prolog/csp_search.plt
*/
:- use_module('../../prolog/csp').
:- use_module(library(plunit)).
:- use_module(library(assoc)).
:- use_module(library(random)).
:- use_module(library(apply)).
:- use_module(library(yall)).

:- begin_tests(csp_search).

fig17_search([], _, R, R).
fig17_search([V|Vs], Net, Asns, R) :-
    csp:choose_one(V, Net, Asns, L),
    fig17_search(Vs, Net, [V/L|Asns], R).

random_net(net(Nodes, Arcs)) :-
    random_between(2, 7, NV),
    numlist(1, NV, Is),
    maplist([I, V]>>atom_concat(v, I, V), Is, Vs),
    maplist([V, V-Ls]>>(random_between(1, 4, K), numlist(1, K, Ls)), Vs, VLs),
    list_to_assoc(VLs, Nodes),
    findall((A-B)-Ps,
            ( member(A, Vs), member(B, Vs), A \== B,
              random(X), X < 0.3,
              get_assoc(A, Nodes, LA), get_assoc(B, Nodes, LB),
              findall(P/Q, ( member(P, LA), member(Q, LB), random(Y), Y < 0.6 ), Ps0),
              sort(Ps0, Ps) ),
            KPs),
    list_to_assoc(KPs, Arcs).

same_answers(0) :- !.
same_answers(N) :-
    random_net(Net),
    Net = net(Nodes, _),
    assoc_to_keys(Nodes, Vs0),
    random_permutation(Vs0, Vs),
    findall(R, fig17_search(Vs, Net, [], R), Want),
    findall(R, csp(Vs, Net, R), Got),
    Got == Want,
    N1 is N - 1,
    same_answers(N1).

test(random_networks) :-
    setup_call_cleanup(
        ( random_property(state(S)), set_random(seed(20261130)) ),
        same_answers(1500),
        set_random(state(S))).

:- end_tests(csp_search).
