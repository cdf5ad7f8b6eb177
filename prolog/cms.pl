/*  spar-py: the constraint manipulation system's geometric network (Sec. 5.2).

    Plan variables that are constrained geometrically (grasp_N, pos_N and the
    initial positions init_posN) are the nodes of a binary constraint network;
    the constraints of Table 1 act on it:

      member(V, Labels)             restrict V's label set (Sec. 5.2.2)
      in_position_class(V, Poses)   restrict V to labels in those stable
                                    poses (Sec. 5.2.3): a stable-pose label
                                    is kept if it is in Poses, an absolute
                                    position label (tr1) if its
                                    kb:position_class/2 is
      reachable(G, P)               an arc G-P of the grasp/position pairs
                                    the robot can realise (Sec. 5.2.4)
      mate_reachable(G, P, Ta)      an arc G-P of the pairs realisable with
                                    the held object at T_P Ta

    After each addition the network is checked with the search of Fig. 17
    (csp.pl); a refused constraint fails (cms_add/4) or is answered
    refused(Reason, Vars) (cms_try/4) and, the network being threaded
    (Net0 -> Net), leaves the old network in force: "the old network is
    restored" costs nothing.

    The network term is cms(Nodes, Arcs, ArcOrder, oracle(Oracle, Memo),
    links(Adj, Empty)): Nodes and Arcs as net/2 of csp.pl, ArcOrder the
    arc keys newest first (for display), Adj an assoc from each variable
    with an arc to the ordset of the variables it has arcs with (so that
    the component of a check, its arcs and the arcs at a restricted node
    are found without a walk of every arc), Empty `true` once some node
    has an empty label set (only an unchecked initial constraint makes
    one), else `false`; Oracle the closure that computes an arc's allowed pairs,
    called as call(Oracle, Kind, Objects, GraspLabels, PosLabels, Pairs)
    with the arguments of foreign:arc_pairs/5 (Kind is reachable or
    mate_reachable(Ta), the constraint without its two variables), and
    Memo its answers so far (a hash table, oracle_pairs/6, kept with nb_setarg/3 across
    backtracking: the oracle is a function of its arguments, and the search
    asks the same question many times). With the plan's search recorder
    (plan_state.pl) and the history's atoms memo (goals.pl) this memo is
    the only Prolog state of phase 1 that backtracking does not undo. The planner uses foreign:arc_pairs
    (the Python kinematics) unless it is given another oracle; Prolog-only
    tests give a table-driven test double.
*/
:- module(cms,
          [ cms_empty/1,             % -Net
            cms_empty/2,             % +Oracle, -Net
            cms_oracle/2,            % +Closure, -Oracle
            cms_empty_with/2,        % +Oracle, -Net
            cms_ask/6,               % +Oracle, +Kind, +Objects, +GLabels, +PLabels, -Pairs
            cms_initial/3,           % +Constraint, +Net0, -Net
            cms_add/4,               % +Constraint, +Objects, +Net0, -Net
            cms_try/4,               % +Constraint, +Objects, +Net0, -Result
            cms_initial_state/3,     % +Fact, +Net0, -Net
            geo_objects/3,           % +Constraint, +OpConds, -Objects
            cms_node/3,              % +Net, ?Var, -Labels
            cms_nodes/2,             % +Net, -VarLabels
            cms_arcs/2,              % +Net, -Arcs
            cms_network/2,           % +Net, -CspNet
            cms_consistent/1,        % +Net
            cms_pruned_nodes/2,      % +Net, -VarLabels
            cms_solution/2,          % +Net, -Assignment
            cms_solution/3,          % +Net, :Choose, -Assignment
            cms_solution/4,          % +Net, :Order, :Choose, -Assignment
            cms_component/3          % +Net, +Vars, -Component
          ]).
:- use_module(library(assoc)).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(ordsets)).
:- use_module(library(error)).
:- use_module(library(yall)).
:- use_module(csp).
:- use_module(foreign, []).
:- use_module(kb, []).

:- meta_predicate cms_empty(5, -), cms_oracle(5, -).

%!  cms_empty(-Net) is det.
%!  cms_empty(:Oracle, -Net) is det.
%
%   The empty network. Arc pairs come from Oracle, by default
%   foreign:arc_pairs/5 (Python), memoised for this network (and the
%   networks made from it) only; see the module header.

cms_empty(Net) :-
    cms_empty(foreign:arc_pairs, Net).

cms_empty(Closure, Net) :-
    cms_oracle(Closure, Oracle),
    cms_empty_with(Oracle, Net).

%!  cms_oracle(:Closure, -Oracle) is det.
%
%   A memoised oracle: Closure's answers kept (in a memo of its own, see
%   the module header) as they are asked through cms_ask/6 or by the
%   networks of cms_empty_with/2. One planning run makes one and shares it
%   between its lower bound and every round of its search: the oracle is
%   a function of its arguments, so an answer is computed once per run.
%
%   ==
%   ?- cms_oracle([_, _, _, _, [a/b]]>>true, O), cms_ask(O, reachable, x, [a], [b], Ps).
%   Ps = [a/b].
%   ==

cms_oracle(Closure, oracle(Closure, Memo)) :-
    memo_buckets(N),
    compound_name_arity(Memo, memo, N),
    forall(between(1, N, I), nb_setarg(I, Memo, end)).

%!  cms_empty_with(+Oracle, -Net) is det.
%
%   The empty network whose arcs come from Oracle (cms_oracle/2), sharing
%   its memo.
%
%   @error type_error(cms_oracle, Oracle) if Oracle is not one.

cms_empty_with(Oracle, cms(Nodes, Arcs, [], Oracle, links(Adj, false))) :-
    (   nonvar(Oracle), Oracle = oracle(_, Memo), compound(Memo), functor(Memo, memo, _)
    ->  true
    ;   type_error(cms_oracle, Oracle)
    ),
    empty_assoc(Nodes),
    empty_assoc(Arcs),
    empty_assoc(Adj).

%!  cms_ask(+Oracle, +Kind, +Objects, +GraspLabels, +PosLabels, -Pairs) is det.
%
%   Pairs is Oracle's answer (cms_oracle/2) for the arguments of
%   foreign:arc_pairs/5, from its memo if it was asked before.

cms_ask(Oracle, Kind, Objects, Gs, Ps, Pairs) :-
    oracle_pairs(Oracle, Kind, Objects, Gs, Ps, Pairs).

%!  cms_initial(+Constraint, +Net0, -Net) is semidet.
%
%   Post an initial constraint of an instantiation rule (Sec. 3.1): for a
%   variable without a node, member(V, Ls) or in_position_class(V, Ls)
%   creates its node with label set Ls and needs no consistency check. On a
%   variable that has a node already it is an ordinary, checked constraint.
%   A named absolute position (a putdown into init_pos1, for a goal
%   part_location(peg, init_pos1)) is no free variable: it gets its node
%   [tr1] first (as cms_initial_state/3 gives it), and the constraint is
%   checked against that.
%
%   @error instantiation_error, type_error(atom, V) or type_error(list, Ls)
%          for a bad member/2 or in_position_class/2 constraint.
%   @error domain_error(initial_constraint, C) for any other constraint.

cms_initial(C, Net0, Net) :-
    unary(C, V, Ls),
    !,
    must_be(atom, V),
    must_be(list, Ls),
    (   cms_node(Net0, V, _)
    ->  cms_add(C, none, Net0, Net)
    ;   kb:position(V, _, _, _)
    ->  initial_node(V, Net0, Net1),
        cms_add(C, none, Net1, Net)
    ;   sort(Ls, Labels),
        put_node(V, Labels, Net0, Net1),
        (   Labels == []
        ->  Net1 = cms(Nodes, Arcs, Order, O, links(Adj, _)),
            Net = cms(Nodes, Arcs, Order, O, links(Adj, true))
        ;   Net = Net1
        )
    ).
cms_initial(C, _, _) :-
    domain_error(initial_constraint, C).

unary(member(V, Ls), V, Ls).
unary(in_position_class(V, Ls), V, Ls).

%!  cms_initial_state(+Fact, +Net0, -Net) is det.
%
%   A goal established by the initial state names absolute positions
%   (part_location(peg, init_pos1)); give each a node whose label set is its
%   single label ([tr1]), from kb:position/4, unless it has one.

cms_initial_state(Fact, Net0, Net) :-
    Fact =.. [_|Args],
    foldl(initial_node, Args, Net0, Net).

initial_node(Name, Net0, Net) :-
    atom(Name),
    kb:position(Name, _, Label, _),
    \+ cms_node(Net0, Name, _),
    !,
    put_node(Name, [Label], Net0, Net).
initial_node(_, Net, Net).

%!  cms_add(+Constraint, +Objects, +Net0, -Net) is semidet.
%
%   Add a geometric constraint (Table 1) and check the network (Figs. 16-17).
%   Fails if the result is inconsistent; Net0 is then still the network.
%   Objects names the objects an arc is about, as foreign:arc_pairs/5
%   expects (see geo_objects/3); unary constraints ignore it.
%
%   @error instantiation_error if a plan variable is unbound.
%   @error existence_error(cms_node, V) if an arc joins a variable without
%          a node.
%   @error domain_error(geometric_constraint, C) for an unknown constraint.

cms_add(Constraint, Objects, Net0, Net) :-
    cms_try(Constraint, Objects, Net0, ok(Net)).

%!  cms_try(+Constraint, +Objects, +Net0, -Result) is det.
%
%   As cms_add/4, but says why a constraint is refused: Result is ok(Net)
%   or refused(Reason, Vars), Reason one of
%
%     - node: a label set would become empty (node consistency); only the
%       unary constraints on Vars = [V] decide this
%     - arc: no pair of the two label sets satisfies the arc; only the
%       label sets of Vars = [G, P] (and an earlier arc between them)
%     - network: the network has no solution; only the constraints of the
%       network component Vars holding the constraint's variables
%
%   The planner uses Vars to jump back to a choice that can matter.
%
%   @error as cms_add/4.

cms_try(member(V, Ls), _, Net0, Result) :-
    !,
    must_be(atom, V),
    must_be(list, Ls),
    sort(Ls, Labels),
    restrict(V, Labels, Net0, Result).
cms_try(in_position_class(V, Classes), _, Net0, Result) :-
    !,
    must_be(atom, V),
    must_be(list, Classes),
    (   cms_node(Net0, V, L0)
    ->  include(in_class(Classes), L0, Labels)
    ;   sort(Classes, Labels)
    ),
    restrict(V, Labels, Net0, Result).
cms_try(reachable(G, P), Obj, Net0, Result) :-
    !,
    add_arc(reachable, Obj, G, P, Net0, Result).
cms_try(mate_reachable(G, P, Ta), Objects, Net0, Result) :-
    !,
    must_be(atom, Ta),
    add_arc(mate_reachable(Ta), Objects, G, P, Net0, Result).
cms_try(C, _, _, _) :-
    domain_error(geometric_constraint, C).

in_class(Classes, Label) :-
    (   memberchk(Label, Classes)
    ->  true
    ;   kb:position_class(Label, Class),
        memberchk(Class, Classes)
    ).

%   restrict(+V, +Labels, +Net0, -Result): node consistency (a non-empty
%   intersection), pruning of the arcs at V, network consistency.

restrict(V, Labels, Net0, Result) :-
    (   cms_node(Net0, V, L0)
    ->  ord_intersection(L0, Labels, L1)
    ;   L1 = Labels
    ),
    (   L1 == []
    ->  Result = refused(node, [V])
    ;   put_node(V, L1, Net0, Net1),
        prune_arcs(V, L1, Net1, Net),
        checked(Net, [V], Result)
    ).

%   checked(+Net, +Vars, -Result): ok(Net) if Net is consistent, else
%   refused(network, Component) for the component of Vars.
%
%   Only the component of Vars is searched: a network is consistent iff
%   each of its components is, and every other component is as it was in
%   the last network accepted, consistent then (a node created by an
%   initial constraint without a check has no arcs: it is consistent
%   unless its label set is empty, which is tested over the whole network
%   here, as the search of the whole network would find it). So the answer
%   is the one of a search of the whole network (cms_consistent/1), at the
%   cost of the component: in a network of N independent pairs a check
%   searches one pair, not N.

checked(Net, Vars, Result) :-
    cms_component(Net, Vars, Component),
    (   no_empty_node(Net),
        component_consistent(Net, Component)
    ->  Result = ok(Net)
    ;   Result = refused(network, Component)
    ).

%   no_empty_node(+Net): no node of Net has an empty label set. Only an
%   initial constraint puts a node unchecked (cms_initial/3, which notes
%   an empty one in links(_, Empty)); a checked one is refused before its
%   node becomes empty, and a node is never removed.

no_empty_node(cms(_, _, _, _, links(_, false))).

%   component_consistent(+Net, +Component): the sub-network of the
%   variables Component (an ordset) and the arcs between them has a
%   solution (csp:consistent/1).

component_consistent(cms(Nodes, Arcs, _, _, links(Adj, _)), Component) :-
    findall(V-Ls, ( member(V, Component), get_assoc(V, Nodes, Ls) ), VLs),
    list_to_assoc(VLs, SubNodes),
    findall(K-Ps, ( member(V1, Component),      % each arc under its key:
                    get_assoc(V1, Adj, Ws),     % one of V1-V2, V2-V1
                    member(V2, Ws),
                    K = V1-V2,
                    get_assoc(K, Arcs, Ps) ),
            KPs0),
    sort(KPs0, KPs),
    list_to_assoc(KPs, SubArcs),
    consistent(net(SubNodes, SubArcs)).

put_node(V, Labels, cms(Nodes0, Arcs, Order, O, L), cms(Nodes, Arcs, Order, O, L)) :-
    put_assoc(V, Nodes0, Labels, Nodes).

%   prune_arcs(+V, +Labels, +Net0, -Net): the pairs of every arc at V
%   whose V label is not in Labels dropped (the arcs at V are those to
%   its neighbours in Adj, each under its key V-W or W-V).

prune_arcs(V, Labels, cms(Nodes, Arcs0, Order, O, links(Adj, E)),
           cms(Nodes, Arcs, Order, O, links(Adj, E))) :-
    (   get_assoc(V, Adj, Ws)
    ->  foldl(prune_arc(V, Labels), Ws, Arcs0, Arcs)
    ;   Arcs = Arcs0
    ).

prune_arc(V, Labels, W, Arcs0, Arcs) :-
    (   get_assoc(V-W, Arcs0, Ps0)
    ->  include(first_in(Labels), Ps0, Ps),
        put_assoc(V-W, Arcs0, Ps, Arcs)
    ;   get_assoc(W-V, Arcs0, Ps0),
        include(second_in(Labels), Ps0, Ps),
        put_assoc(W-V, Arcs0, Ps, Arcs)
    ).

first_in(Labels, A/_) :- ord_memberchk(A, Labels).
second_in(Labels, _/B) :- ord_memberchk(B, Labels).

%   add_arc(+Kind, +Objects, +G, +P, +Net0, -Result): exhaustive pairing
%   of the two label sets through the oracle (Sec. 5.2.4); a second
%   constraint on the same two nodes intersects with the arc already there.

add_arc(Kind, Objects, G, P, Net0, Result) :-
    must_be(atom, G),
    must_be(atom, P),
    node_labels(Net0, G, Gs),
    node_labels(Net0, P, Ps),
    Net0 = cms(Nodes, Arcs0, Order0, Oracle, Links0),
    oracle_pairs(Oracle, Kind, Objects, Gs, Ps, Pairs0),
    include(pair_in(Gs, Ps), Pairs0, Pairs1),
    sort(Pairs1, Pairs2),
    (   get_assoc(G-P, Arcs0, Old)
    ->  ord_intersection(Old, Pairs2, Pairs), Key = G-P, Order = Order0
    ;   get_assoc(P-G, Arcs0, Old)
    ->  maplist([A/B, B/A]>>true, Pairs2, Flipped0),
        sort(Flipped0, Flipped),
        ord_intersection(Old, Flipped, Pairs), Key = P-G, Order = Order0
    ;   Pairs = Pairs2, Key = G-P, Order = [G-P|Order0]
    ),
    (   Pairs == []
    ->  Result = refused(arc, [G, P])
    ;   put_assoc(Key, Arcs0, Pairs, Arcs),
        (   Order == Order0
        ->  Links = Links0
        ;   link(G, P, Links0, Links)
        ),
        checked(cms(Nodes, Arcs, Order, Oracle, Links), [G, P], Result)
    ).

%   link(+V1, +V2, +Links0, -Links): V1 and V2 neighbours in the
%   adjacency of links(Adj, Empty).

link(V1, V2, links(Adj0, E), links(Adj, E)) :-
    add_neighbour(V1, V2, Adj0, Adj1),
    add_neighbour(V2, V1, Adj1, Adj).

add_neighbour(V, W, Adj0, Adj) :-
    (   get_assoc(V, Adj0, Ws0)
    ->  ord_add_element(Ws0, W, Ws)
    ;   Ws = [W]
    ),
    put_assoc(V, Adj0, Ws, Adj).

%   The memo is memo(B1, ..., Bn), a hash table of n buckets (the key's
%   term_hash/2; a key that is not ground goes to the first), each a chain
%   e(Key, Pairs, Next) ending in `end`. An answer is added by nb_setarg/3
%   on the chain's last link, which copies the new entry only: an assoc
%   put back with nb_setarg/3 would be copied whole at every miss (at
%   N = 50 generated parts, 250 misses of a growing memo).

memo_buckets(64).

oracle_pairs(oracle(Closure, Memo), Kind, Objects, Gs, Ps, Pairs) :-
    Key = q(Kind, Objects, Gs, Ps),
    term_hash(Key, H),
    (   integer(H)
    ->  functor(Memo, _, N),
        I is H mod N + 1
    ;   I = 1
    ),
    memo_get(Memo, I, Key, Found),
    (   Found = found(Pairs0)
    ->  Pairs = Pairs0
    ;   Found = last(Link, Arg),
        call(Closure, Kind, Objects, Gs, Ps, Pairs),
        must_be(list, Pairs),
        nb_setarg(Arg, Link, e(Key, Pairs, end))
    ).

%   memo_get(+Link, +Arg, +Key, -Found): Found is found(Pairs), Pairs Key's
%   answer in the chain from argument Arg of Link, or last(L, A) if the
%   chain has none, L and A the link and argument that end it.

memo_get(Link, Arg, Key, Found) :-
    arg(Arg, Link, Next),
    (   Next == end
    ->  Found = last(Link, Arg)
    ;   Next = e(K, P, _),
        (   K == Key
        ->  Found = found(P)
        ;   memo_get(Next, 3, Key, Found)
        )
    ).

node_labels(Net, V, Labels) :-
    (   cms_node(Net, V, Labels)
    ->  true
    ;   existence_error(cms_node, V)
    ).

pair_in(Gs, Ps, G/P) :-
    ord_memberchk(G, Gs),
    ord_memberchk(P, Ps).

%!  geo_objects(+Constraint, +OpConds:list, -Objects) is det.
%
%   The objects a geometric constraint is about, read from the operational
%   conditions of its geometric goal (Sec. 3.4): reachable(G, P) is about
%   the Obj of holding(Obj, G) or part_location(Obj, P); mate_reachable(G,
%   P, Ta) about Held-Fixed from holding(Held, G) and part_location(Fixed,
%   P). Unary constraints are about no object (none).
%
%   @error domain_error(geo_goal, Constraint-OpConds) if they cannot be read.

geo_objects(reachable(G, P), Conds, Obj) :-
    (   member(holding(Obj, G1), Conds), G1 == G
    ;   member(part_location(Obj, P1), Conds), P1 == P
    ),
    atom(Obj),
    !.
geo_objects(mate_reachable(G, P, _), Conds, Held-Fixed) :-
    member(holding(Held, G1), Conds), G1 == G,
    member(part_location(Fixed, P1), Conds), P1 == P,
    !.
geo_objects(C, _, none) :-
    unary(C, _, _),
    !.
geo_objects(C, Conds, _) :-
    domain_error(geo_goal, C-Conds).

%!  cms_node(+Net, ?Var, -Labels) is nondet.
%
%   Var has a node with label set Labels (an ordset).

cms_node(cms(Nodes, _, _, _, _), V, Labels) :-
    (   atom(V)
    ->  get_assoc(V, Nodes, Labels)
    ;   gen_assoc(V, Nodes, Labels)
    ).

%!  cms_nodes(+Net, -VarLabels:list) is det.
%
%   All nodes as Var-Labels, in standard order of Var (the raw label sets,
%   restricted only by unary constraints, as the paper's Fig. 25 shows them).

cms_nodes(cms(Nodes, _, _, _, _), VarLabels) :-
    assoc_to_list(Nodes, VarLabels).

%!  cms_arcs(+Net, -Arcs:list) is det.
%
%   All arcs as arc(V1, V2, Pairs), oldest first; Pairs are V1Label/V2Label.

cms_arcs(cms(_, Arcs, Order, _, _), List) :-
    reverse(Order, Keys),
    maplist(arc_of(Arcs), Keys, List).

arc_of(Arcs, V1-V2, arc(V1, V2, Pairs)) :-
    get_assoc(V1-V2, Arcs, Pairs).

%!  cms_network(+Net, -CspNet) is det.
%
%   The net(Nodes, Arcs) term csp.pl works on.

cms_network(cms(Nodes, Arcs, _, _, _), net(Nodes, Arcs)).

%!  cms_consistent(+Net) is semidet.
%
%   Some assignment of labels satisfies every arc (Figs. 16-17).

cms_consistent(Net) :-
    cms_network(Net, CspNet),
    consistent(CspNet).

%!  cms_pruned_nodes(+Net, -VarLabels:list) is semidet.
%
%   The label sets after arc consistency (AC-3), as Var-Labels: what a user
%   can still choose. Fails only if Net is inconsistent.

cms_pruned_nodes(Net, VarLabels) :-
    cms_network(Net, CspNet),
    ac3(CspNet, Nodes),
    assoc_to_list(Nodes, VarLabels).

%!  cms_solution(+Net, -Assignment:list) is nondet.
%
%   A solution of the network as Var-Label pairs; all of them on
%   backtracking, lazily.

cms_solution(Net, Assignment) :-
    cms_network(Net, CspNet),
    solution(CspNet, Assignment).

:- meta_predicate cms_solution(+, 4, -).

%!  cms_solution(+Net, :Choose, -Assignment:list) is nondet.
%
%   As cms_solution/2, the labels of each variable V tried in the order
%   call(Choose, V, LabelSet, Assigned, Labels) gives (csp:solution/3).

cms_solution(Net, Choose, Assignment) :-
    cms_network(Net, CspNet),
    solution(CspNet, Choose, Assignment).

:- meta_predicate cms_solution(+, 2, 4, -).

%!  cms_solution(+Net, :Order, :Choose, -Assignment:list) is nondet.
%
%   As cms_solution/3, the variables searched in the order call(Order,
%   Vars0, Vars) makes of the first-fail order (csp:solution/4).

cms_solution(Net, Order, Choose, Assignment) :-
    cms_network(Net, CspNet),
    solution(CspNet, Order, Choose, Assignment).

%!  cms_component(+Net, +Vars:list, -Component:list) is det.
%
%   Component is the ordset of Vars and every variable joined to one of
%   them by a path of arcs (whether or not it has a node yet).

cms_component(cms(_, _, _, _, links(Adj, _)), Vars, Component) :-
    sort(Vars, Start),
    grow_component(Start, Start, Adj, Component).

%   grow_component(+Frontier, +C0, +Adj, -C): C is C0 (an ordset holding
%   Frontier) and every variable reached from Frontier through Adj.

grow_component(Frontier, C0, Adj, C) :-
    findall(W, ( member(V, Frontier),
                 get_assoc(V, Adj, Ws),
                 member(W, Ws),
                 \+ ord_memberchk(W, C0) ),
            New0),
    (   New0 == []
    ->  C = C0
    ;   sort(New0, New),
        ord_union(C0, New, C1),
        grow_component(New, C1, Adj, C)
    ).
