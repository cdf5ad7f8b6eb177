/*  Tests of prolog/cms.pl: the geometric network of Sec. 5.2 with a
    table-driven arc oracle (a test double for foreign:arc_pairs/5).

    swipl -g run_tests -t halt tests/prolog/cms.plt
*/
:- use_module('../../prolog/spar').
:- use_module('../../prolog/cms').
:- use_module(fixtures/paper_cell).
:- use_module(library(plunit)).
:- use_module(library(apply)).
:- use_module(library(yall)).

:- begin_tests(cms_sec5_2, [setup(load_cell(hole_down))]).

oracle(fixture_paper_cell:table_oracle(hole_down)).

%   The peg's grasp node and its initial position, as after goal_7 of Sec. 6.

peg_net(Net) :-
    oracle(O),
    cms_empty(O, N0),
    spar_actions:get_all_grasps(peg, Gs),
    cms_initial(member(grasp_1, Gs), N0, N1),
    cms_initial_state(part_location(peg, init_pos1), N1, Net).

test(default_oracle_is_python, O == foreign:arc_pairs) :-
    cms_empty(cms(_, _, _, oracle(O, _), _)).

test(initial_constraint_creates_node, L == [p2P1, p2P2]) :-
    cms_empty(N0),
    cms_initial(in_position_class(pos_1, [p2P2, p2P1]), N0, N),
    cms_node(N, pos_1, L).

%   A putdown into a named absolute position (a white knight for a goal
%   part_location(peg, init_pos1)) constrains that position, whose only
%   label is tr1 (class p1P5), not a free variable over stable poses.

test(initial_constraint_on_absolute_position, L == [tr1]) :-
    cms_empty(N0),
    spar_actions:get_all_poses(peg, Ps),
    cms_initial(in_position_class(init_pos1, Ps), N0, N),
    cms_node(N, init_pos1, L).

test(initial_constraint_on_absolute_position_other_class, fail) :-
    cms_empty(N0),
    cms_initial(in_position_class(init_pos1, [p1P1, p1P2]), N0, _).

test(initial_state_single_label, L == [tr1]) :-
    peg_net(N),
    cms_node(N, init_pos1, L).

test(sec5_2_2_member_intersects, L == [p1G12, p1G3]) :-
    peg_net(N0),
    cms_add(member(grasp_1, [p1G3, p1G12, nosuch]), none, N0, N),
    cms_node(N, grasp_1, L).

test(member_empty_refused, R == refused(node, [grasp_1])) :-
    peg_net(N0),
    cms_try(member(grasp_1, [nosuch]), none, N0, R).

test(fig25_reachable_arc, Arcs == [arc(grasp_1, init_pos1, [p1G12/tr1, p1G3/tr1, p1G7/tr1, p1G8/tr1])]) :-
    peg_net(N0),
    cms_add(reachable(grasp_1, init_pos1), peg, N0, N),
    cms_arcs(N, Arcs).

test(unary_prunes_arc, Arcs == [arc(grasp_1, init_pos1, [p1G3/tr1])]) :-
    peg_net(N0),
    cms_add(reachable(grasp_1, init_pos1), peg, N0, N1),
    cms_add(member(grasp_1, [p1G1, p1G3]), none, N1, N),
    cms_arcs(N, Arcs).

test(raw_label_set_kept_by_arc, L == 20) :-
    peg_net(N0),
    cms_add(reachable(grasp_1, init_pos1), peg, N0, N),
    cms_node(N, grasp_1, Ls),
    length(Ls, L).

test(pruned_label_set, L == [p1G12, p1G3, p1G7, p1G8]) :-
    peg_net(N0),
    cms_add(reachable(grasp_1, init_pos1), peg, N0, N),
    cms_pruned_nodes(N, Pruned),
    memberchk(grasp_1-L, Pruned).

%   Sec. 5.2.4: "If the consistency check fails, the CMS signals failure and
%   the old network is restored."

test(restoration_after_network_refusal, [Before == After, R = refused(network, _)]) :-
    peg_net(N0),
    cms_add(reachable(grasp_1, init_pos1), peg, N0, N1),
    cms_nodes(N1, Before),
    cms_try(member(grasp_1, [p1G1, p1G9]), none, N1, R),
    cms_nodes(N1, After),
    cms_consistent(N1).

test(restoration_after_arc_refusal, L == [p1G3]) :-
    peg_net(N0),
    cms_add(reachable(grasp_1, init_pos1), peg, N0, N1),
    \+ cms_add(mate_reachable(grasp_1, init_pos1, trans_1), peg-peg, N1, _),
    cms_add(member(grasp_1, [p1G1, p1G3]), none, N1, N2),
    cms_pruned_nodes(N2, Pruned),
    memberchk(grasp_1-L, Pruned).

test(sec5_2_3_position_class_absolute_refused, fail) :-
    cms_empty(N0),
    cms_initial_state(part_location(block, init_pos2), N0, N1),
    cms_add(in_position_class(init_pos2, [p2P1, p2P2, p2P4, p2P5, p2P6]), none, N1, _).

test(position_class_absolute_kept, L == [tr2]) :-
    cms_empty(N0),
    cms_initial_state(part_location(block, init_pos2), N0, N1),
    cms_add(in_position_class(init_pos2, [p2P3]), none, N1, N),
    cms_node(N, init_pos2, L).

test(position_class_pose, L == [p2P1, p2P2, p2P4, p2P5, p2P6]) :-
    spar_actions:get_all_poses(block, Ps),
    cms_empty(N0),
    cms_initial(in_position_class(pos_1, Ps), N0, N1),
    cms_add(in_position_class(pos_1, [p2P1, p2P2, p2P4, p2P5, p2P6]), none, N1, N),
    cms_node(N, pos_1, L).

%   A second constraint on the same two nodes (here an oracle that allows
%   only p1G3/tr1) intersects with the arc already there.

test(second_arc_intersects, Arcs == [arc(grasp_1, init_pos1, [p1G3/tr1])]) :-
    peg_net(N0),
    cms_add(reachable(grasp_1, init_pos1), peg, N0, N1),
    N1 = cms(Nodes, As, Order, _, Links),
    cms_empty([_, _, _, _, [p1G3/tr1]]>>true, cms(_, _, _, Oracle, _)),
    cms_add(reachable(grasp_1, init_pos1), peg, cms(Nodes, As, Order, Oracle, Links), N),
    cms_arcs(N, Arcs).

test(component, C == [grasp_1, init_pos1]) :-
    peg_net(N0),
    cms_add(reachable(grasp_1, init_pos1), peg, N0, N),
    cms_component(N, [init_pos1], C).

test(geo_objects_mate, O == peg-block) :-
    geo_objects(mate_reachable(grasp_1, pos_1, trans_1),
                [holding(peg, grasp_1), part_location(block, pos_1)], O).

test(missing_node, [error(existence_error(cms_node, pos_9))]) :-
    peg_net(N0),
    cms_add(reachable(grasp_1, pos_9), peg, N0, _).

test(unbound_variable, [error(instantiation_error)]) :-
    peg_net(N0),
    cms_add(member(_, [p1G1]), none, N0, _).

test(unknown_constraint, [error(domain_error(geometric_constraint, near(a, b)))]) :-
    peg_net(N0),
    cms_add(near(a, b), none, N0, _).

counting_oracle(Count, K, O, Gs, Ps, Pairs) :-
    arg(1, Count, C0),
    C is C0 + 1,
    nb_setarg(1, Count, C),
    table_oracle(hole_down, K, O, Gs, Ps, Pairs).

%   The oracle (Python: inverse kinematics) is asked each question once.

test(oracle_asked_once, N == 1) :-
    Count = count(0),
    cms_empty(counting_oracle(Count), N0),
    spar_actions:get_all_grasps(peg, Gs),
    cms_initial(member(grasp_1, Gs), N0, N1),
    cms_initial_state(part_location(peg, init_pos1), N1, N2),
    cms_add(reachable(grasp_1, init_pos1), peg, N2, _),
    cms_add(reachable(grasp_1, init_pos1), peg, N2, _),
    arg(1, Count, N).

%   More questions than the memo has buckets (chains of several entries),
%   a non-ground one among them, each asked twice: each reaches the oracle
%   once and gets its own answer back, after backtracking too.

echo_oracle(Count, K, O, Gs, Ps, [K/O/Gs/Ps]) :-
    arg(1, Count, C0),
    C is C0 + 1,
    nb_setarg(1, Count, C).

test(memo_many_questions, [N-Bad == 201-[]]) :-
    Count = count(0),
    cms_empty(echo_oracle(Count), Net),
    Net = cms(_, _, _, Oracle, _),
    numlist(1, 200, Is),
    Qs = [q(k(_), o, [g], [p])|Qs0],
    findall(q(k(I), o, [g], [p]), member(I, Is), Qs0),
    forall(member(q(K, O, Gs, Ps), Qs),
           \+ \+ cms:oracle_pairs(Oracle, K, O, Gs, Ps, _)),
    findall(K, ( member(q(K, O, Gs, Ps), Qs0),
                 cms:oracle_pairs(Oracle, K, O, Gs, Ps, Pairs),
                 Pairs \== [K/O/Gs/Ps] ), Bad),
    arg(1, Count, N).

%   cms_oracle/2: one memo shared by cms_ask/6 and the networks made with
%   cms_empty_with/2 (a run's lower bound and its rounds).

test(shared_oracle_asked_once, N-Pairs == 1-[p1G12/tr1, p1G3/tr1, p1G7/tr1, p1G8/tr1]) :-
    Count = count(0),
    cms_oracle(counting_oracle(Count), Oracle),
    spar_actions:get_all_grasps(peg, Gs0),
    sort(Gs0, Gs),
    cms_ask(Oracle, reachable, peg, Gs, [tr1], Pairs0),
    cms_empty_with(Oracle, N0),
    cms_initial(member(grasp_1, Gs), N0, N1),
    cms_initial_state(part_location(peg, init_pos1), N1, N2),
    cms_add(reachable(grasp_1, init_pos1), peg, N2, N3),
    cms_arcs(N3, [arc(grasp_1, init_pos1, Pairs)]),
    Pairs0 == Pairs,
    arg(1, Count, N).

test(shared_oracle_doc_example, Ps == [a/b]) :-
    cms_oracle([_, _, _, _, [a/b]]>>true, O),
    cms_ask(O, reachable, x, [a], [b], Ps).

test(empty_with_not_an_oracle, [error(type_error(cms_oracle, foo))]) :-
    cms_empty_with(foo, _).


%   Random networks (a hashing oracle over made-up labels): after every
%   accepted constraint the component of each variable (found through the
%   adjacency) is the one the listed arcs give, the arcs at a restricted
%   node keep only its labels, and the whole network is consistent.
%   Fails if the adjacency misses an arc, or a check skips a part of the
%   network it should have searched.

hash_oracle(Kind, _, Gs, Ps, Pairs) :-
    findall(G/P, ( member(G, Gs), member(P, Ps),
                   term_hash(Kind-G-P, H), H mod 3 =\= 0 ),
            Pairs).

random_step(Vars, Net0, Net) :-
    random_member(Which, [arc, arc, member]),
    (   Which == arc
    ->  random_member(G, Vars), random_member(P, Vars), G \== P,
        C = reachable(G, P)
    ;   random_member(V, Vars),
        random_member(L1, [a1, a2, a3, a4, a5]),
        random_member(L2, [a1, a2, a3, a4, a5]),
        C = member(V, [L1, L2, a6])
    ),
    (   cms_try(C, obj, Net0, ok(Net1))
    ->  Net = Net1
    ;   Net = Net0
    ).

arcs_component(Net, V, C) :-
    cms_arcs(Net, Arcs),
    arcs_closure([V], Arcs, C).

arcs_closure(C0, Arcs, C) :-
    findall(W, ( member(arc(A, B, _), Arcs),
                 ( memberchk(A, C0) -> W = B ; memberchk(B, C0), W = A ) ),
            Ws),
    append(C0, Ws, C1s),
    sort(C1s, C1),
    (   C1 == C0 -> C = C0 ; arcs_closure(C1, Arcs, C) ).

arc_labels_in(Net, arc(A, B, Pairs)) :-
    cms_node(Net, A, LA), cms_node(Net, B, LB),
    forall(member(X/Y, Pairs), ( memberchk(X, LA), memberchk(Y, LB) )).

network_invariants(Vars, Net) :-
    forall(member(V, Vars),
           ( cms_component(Net, [V], C1), arcs_component(Net, V, C2), C1 == C2 )),
    cms_arcs(Net, Arcs),
    forall(member(A, Arcs), arc_labels_in(Net, A)),
    cms_consistent(Net).

test(random_networks_adjacency, Bad == []) :-
    Vars = [v1, v2, v3, v4, v5, v6, v7, v8],
    findall(Seed-K,
            ( between(1, 15, Seed),
              set_random(seed(Seed)),
              cms_empty(hash_oracle, N0),
              foldl(initial_labels, Vars, N0, N1),
              numlist(1, 25, Ks),
              foldl(checked_step(Vars), Ks, N1-[], _-Bs),
              member(K, Bs) ),
            Bad).

initial_labels(V, Net0, Net) :-
    cms_initial(member(V, [a1, a2, a3, a4, a5, a6]), Net0, Net).

checked_step(Vars, K, Net0-Bad0, Net-Bad) :-
    random_step(Vars, Net0, Net),
    (   network_invariants(Vars, Net) -> Bad = Bad0 ; Bad = [K|Bad0] ).

%   An initial constraint with no label leaves an empty node: every later
%   check is refused, as a search of the whole network would find.

test(empty_initial_node_refuses, R = refused(network, _)) :-
    peg_net(N0),
    cms_initial(member(grasp_9, []), N0, N1),
    \+ cms_consistent(N1),
    cms_try(member(grasp_1, [p1G3, p1G7]), none, N1, R).

:- end_tests(cms_sec5_2).
