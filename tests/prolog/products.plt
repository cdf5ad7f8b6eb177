/*  Tests of establish:post_precedence/3: the orderings a product's
    geometry forces (kb:precedence/3, world/product/products.py) posted between the
    assembles of the parts, on the paper cell's knowledge base with two
    assembles (peg into block, block onto peg: only their parts matter).

    swipl -g run_tests -t halt tests/prolog/products.plt
*/
:- use_module('../../prolog/spar').
:- use_module('../../prolog/goals').
:- use_module('../../prolog/plan_state', except([plan_actions/2])).
:- use_module('../../prolog/establish').
:- use_module('../../prolog/ordering').
:- use_module(fixtures/paper_cell).
:- use_module(library(plunit)).
:- use_module(library(apply)).

:- begin_tests(post_precedence).

load(Precedence) :-
    cell_facts(hole_down, Facts0),
    append(Facts0, Precedence, Facts),
    kb:replace_facts(Facts).

plan0(P) :-
    initial_plan(10, [oracle(fixture_paper_cell:table_oracle(hole_down))], P).

two_assembles(P0, P) :-
    foldl([C, X0, X]>>once(new_action(C, _, [], X0, X)),
          [ assembled(peg, block, [[peg_face], [block_face]], trans_1, vec_1),
            assembled(block, peg, [[b2], [base_top]], trans_1, vec_1) ],
          P0, P).

arcs(P, Arcs) :-
    plan_order(P, G),
    ordering_arcs(G, Arcs).

test(posted_when_the_second_enters, Arcs == [prior_to(action_1, action_2)]) :-
    load([precedence(peg, block, 'peg\'s insertion would pass through block')]),
    plan0(P0),
    two_assembles(P0, P),
    arcs(P, Arcs).

test(posted_the_other_way, Arcs == [prior_to(action_2, action_1)]) :-
    load([precedence(block, peg, 'block\'s insertion would pass through peg')]),
    plan0(P0),
    two_assembles(P0, P),
    arcs(P, Arcs).

test(none_without_a_product, Arcs == []) :-
    load([]),
    plan0(P0),
    two_assembles(P0, P),
    arcs(P, Arcs).

test(cycle_refused, fail) :-
    load([]),
    plan0(P0),
    two_assembles(P0, P1),
    post_prior_to(action_2, action_1, P1, P2),
    load([precedence(peg, block, r)]),
    plan_state:plan_actions(P2, As),
    member(A, As),
    A = action(action_1, _, _, _, _),
    post_precedence(A, P2, _).

test(not_an_action, error(type_error(action, foo(1)))) :-
    load([]),
    plan0(P0),
    post_precedence(foo(1), P0, _).

:- end_tests(post_precedence).
