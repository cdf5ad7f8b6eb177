/*  Tests of prolog/ordering.pl: the ordering graph of Sec. 5.1 (Fig. 14).

    swipl -g run_tests -t halt tests/prolog/ordering.plt
*/
:- use_module('../../prolog/spar').
:- use_module('../../prolog/ordering').
:- use_module(library(plunit)).
:- use_module(library(apply)).
:- use_module(library(ugraphs)).
:- use_module(library(lists)).
:- use_module(library(random)).
:- use_module(library(yall)).

:- begin_tests(ordering_sec5_1).

graph(Arcs, G) :-
    empty_ordering(G0),
    foldl([A-B, X0, X]>>( ordering_add_action(A, X0, X1),
                          ordering_add_action(B, X1, X2),
                          prior_to(A, B, X2, X) ),
          Arcs, G0, G).

test(prior_to_adds_arc, PriorTos == [prior_to(action_2, action_1)]) :-
    graph([action_2-action_1], G),
    ordering_arcs(G, PriorTos).

test(fig14_cycle_refused, fail) :-
    graph([a1-a2, a2-a3], G),
    prior_to(a3, a1, G, _).

test(self_refused, fail) :-
    graph([a1-a2], G),
    prior_to(a1, a1, G, _).

test(repeated_arc_is_noop, G == G1) :-
    graph([a1-a2], G),
    prior_to(a1, a2, G, G1).

test(start_precedes_everything, G == G1) :-
    graph([a1-a2], G),
    prior_to(start, a2, G, G1).

test(nothing_before_start, fail) :-
    graph([a1-a2], G),
    prior_to(a1, start, G, _).

test(nothing_after_finish, fail) :-
    graph([a1-a2], G),
    prior_to(finish, a1, G, _).

test(necessarily_before_transitive) :-
    graph([a1-a2, a2-a3], G),
    necessarily_before(a1, a3, G),
    \+ necessarily_before(a3, a1, G).

test(possibly_between_unordered) :-
    graph([e-s], G0),
    ordering_add_action(c, G0, G),
    possibly_between(c, e, s, G).

test(not_between_after_s, fail) :-
    graph([e-s, s-c], G),
    possibly_between(c, e, s, G).

test(not_between_before_e, fail) :-
    graph([c-e, e-s], G),
    possibly_between(c, e, s, G).

test(linearisations, Ls == [[a, b, c], [a, c, b], [b, a, c]]) :-
    empty_ordering(G0),
    foldl(ordering_add_action, [a, b, c], G0, G1),
    prior_to(a, c, G1, G),
    findall(L, linearisation(G, L), Ls).

test(linearisation_total_order, Ls == [[action_4, action_3, action_2, action_1]]) :-
    graph([action_2-action_1, action_3-action_1, action_3-action_2,
           action_4-action_3], G),
    findall(L, linearisation(G, L), Ls).

%   linearisation/3 gives exactly the linearisations of linearisation/2
%   none of whose prefixes its test refuses, in the same order: here no
%   d right after b, and no c once a and d are both done.

refused(Done, V) :-
    (   last(Done, b), V == d
    ;   V == c, memberchk(a, Done), memberchk(d, Done)
    ).

allowed(Done, V) :- \+ refused(Done, V).

prefixes_allowed(L) :-
    \+ ( append(Done, [V|_], L), refused(Done, V) ).

test(linearisations_pruned, Pruned == Filtered) :-
    empty_ordering(G0),
    foldl(ordering_add_action, [a, b, c, d], G0, G1),
    prior_to(a, c, G1, G),
    findall(L, linearisation(G, allowed, L), Pruned),
    findall(L, ( linearisation(G, L), prefixes_allowed(L) ), Filtered),
    Filtered \== [],
    findall(L, linearisation(G, L), All),
    length(All, NA), length(Filtered, NF), NF < NA.

%   linearisation/4 threads its state through each prefix: here the
%   number of actions placed, c refused as the first.

test(linearisations_threaded, Ls == [[a, b, c], [a, c, b], [b, a, c], [b, c, a]]) :-
    empty_ordering(G0),
    foldl(ordering_add_action, [a, b, c], G0, G),
    findall(L, linearisation(G, [V, N0, N]>>(N is N0 + 1, (V == c -> N > 1 ; true)), 0, L), Ls).

test(linearisations_threaded_as_pruned, Threaded == Pruned) :-
    empty_ordering(G0),
    foldl(ordering_add_action, [a, b, c, d], G0, G1),
    prior_to(a, c, G1, G),
    findall(L, linearisation(G, [V, D0, D]>>(allowed(D0, V), append(D0, [V], D)), [], L), Threaded),
    findall(L, linearisation(G, allowed, L), Pruned).

test(type_error, [error(type_error(atom, 1))]) :-
    empty_ordering(G),
    prior_to(1, a, G, _).

%   The closure kept incrementally against library(ugraphs)'s
%   transitive_closure/2 of the posted arcs, on random graphs of 12
%   actions: every pair, every accepted and refused arc.

random_graph(Seed, G, U) :-
    random_graph(Seed, 12, 40, G, U).

%   random_graph(+Seed, +Actions, +Arcs, -G, -U): Actions actions, Arcs
%   random arcs tried (those closing a cycle refused).

random_graph(Seed, NA, NArcs, G, U) :-
    set_random(seed(Seed)),
    numlist(1, NA, Is),
    maplist([I, A]>>atom_concat(a, I, A), Is, As),
    empty_ordering(G0),
    foldl(ordering_add_action, As, G0, G1),
    numlist(1, NArcs, Ks),
    foldl(random_arc(As), Ks, G1, G),
    ordering_graph(G, U).

random_arc(As, _, G0, G) :-
    random_member(A1, As),
    random_member(A2, As),
    (   prior_to(A1, A2, G0, G1) -> G = G1 ; G = G0 ).

test(closure_matches_ugraphs, Bad == []) :-
    findall(Seed-A1-A2,
            ( between(1, 25, Seed),
              random_graph(Seed, G, U),
              transitive_closure(U, C),
              vertices(U, Vs),
              member(A1, Vs), member(A2, Vs),
              (   memberchk(A1-Ns, C), memberchk(A2, Ns) -> Want = true ; Want = false ),
              (   necessarily_before(A1, A2, G) -> Got = true ; Got = false ),
              Want \== Got ),
            Bad).

%   ... and on sparser graphs of 40 actions, where an arc joins few
%   actions (the closure updated node by node) as well as many (in one
%   pass over all nodes): every graph after each of its arcs.

test(closure_matches_ugraphs_both_updates, Bad == []) :-
    findall(Seed-NArcs-A1-A2,
            ( between(1, 4, Seed),
              member(NArcs, [5, 15, 30, 60]),
              random_graph(Seed, 40, NArcs, G, U),
              transitive_closure(U, C),
              vertices(U, Vs),
              member(A1, Vs), member(A2, Vs),
              (   memberchk(A1-Ns, C), memberchk(A2, Ns) -> Want = true ; Want = false ),
              (   necessarily_before(A1, A2, G) -> Got = true ; Got = false ),
              Want \== Got ),
            Bad).

test(refused_iff_cycle, Bad == []) :-
    findall(Seed-A1-A2,
            ( between(1, 10, Seed),
              random_graph(Seed, G, U),
              transitive_closure(U, C),
              vertices(U, Vs),
              member(A1, Vs), member(A2, Vs), A1 \== A2,
              (   memberchk(A2-Ns, C), memberchk(A1, Ns) -> Want = fail ; Want = ok ),
              (   prior_to(A1, A2, G, _) -> Got = ok ; Got = fail ),
              Want \== Got ),
            Bad).

test(outside_mask_is_possibly_between, Bad == []) :-
    findall(Seed-C-E-S,
            ( between(1, 10, Seed),
              random_graph(Seed, G, U),
              vertices(U, Vs),
              member(E, [start|Vs]), member(S, [finish|Vs]), member(C, Vs),
              outside_mask(E, S, G, Mask),
              ordering_bit(C, G, B),
              (   B /\ Mask =:= 0 -> Got = true ; Got = false ),
              (   possibly_between(C, E, S, G) -> Want = true ; Want = false ),
              Want \== Got ),
            Bad).

%   ancestors_mask/3 is the union of the ancestors of the actions of a
%   set, whichever set (its skipping of ancestors already covered must not
%   drop one that is not): random graphs, random subsets of their actions.

test(ancestors_mask_is_union, Bad == []) :-
    findall(Seed-K,
            ( between(1, 10, Seed),
              random_graph(Seed, G, U),
              vertices(U, Vs),
              between(1, 8, K),
              findall(V, ( member(V, Vs), random(0, 3, R), R =:= 0 ), Set),
              foldl(or_bit(G), Set, 0, Bits),
              ancestors_mask(Bits, G, Got),
              findall(A, ( member(A, Vs), member(D, Set), necessarily_before(A, D, G) ), As0),
              sort(As0, As),
              foldl(or_bit(G), As, 0, Want),
              Got =\= Want ),
            Bad).

or_bit(G, V, B0, B) :-
    ordering_bit(V, G, X),
    B is B0 \/ X.

test(ancestors_mask_empty, M == 0) :-
    empty_ordering(G0),
    prior_to(a, b, G0, G),
    ancestors_mask(0, G, M).

test(graph_is_a_ugraph, U == [a-[b, c], b-[c], c-[]]) :-
    graph([a-b, b-c, a-c], G),
    ordering_graph(G, U).

:- end_tests(ordering_sec5_1).
