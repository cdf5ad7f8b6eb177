/*  spar-py: the ordering graph of phase 1 (Sec. 5.1, Fig. 14).

    Ordering constraints prior_to(Action1, Action2) are the arcs of a directed
    graph over the plan's action ids, threaded through the planner (G0 -> G).
    A constraint is refused when it would close a cycle, that is when there
    is already a path from Action2 to Action1.

    The graph is kept with its transitive closure, so that the questions the
    planner asks at every step (is there a path A1 -> A2? may C fall between
    E and S?) cost two O(log n) look-ups, not a search of the graph:

      ord(Nodes, Of, N)

    Nodes is an assoc from each action id to n(I, Succs, Desc, Anc): I its
    number (0, 1, ...), Succs the ordset of the ids it has posted arcs to,
    Desc and Anc the sets of its strict descendants and ancestors as
    bitsets (integers; bit J is the action numbered J). Of maps each number
    back to its id, and N is the next number. Posting an arc A1 -> A2 not
    yet implied adds Desc(A2) and A2 to the descendants of A1 and of every
    ancestor of A1, and Anc(A1) and A1 to the ancestors of A2 and of every
    descendant of A2: the closure stays exact, at a cost of the sizes of
    those two sets (each update O(log n)). The posted arcs themselves are
    kept too (ordering_arcs/2, ordering_graph/2): they are what Fig. 24
    shows.

    Two virtual actions bound every plan and are never stored: `start`, the
    null action whose add list is the initial state (Sec. 7.1), precedes every
    action; `finish`, at which the user's goals must hold, follows every
    action. So prior_to(start, A) and prior_to(A, finish) always hold and add
    no arc, while prior_to(A, start) and prior_to(finish, A) are refused.

    The partial plan of phase 1 gives the graph to its readers as a
    library(ugraphs) graph (ordering_graph/2); ordering_arcs/2,
    ordering_actions/2 and linearisation/2 take either form.
*/
:- module(ordering,
          [ empty_ordering/1,          % -G
            ordering_add_action/3,     % +Id, +G0, -G
            prior_to/4,                % +A1, +A2, +G0, -G
            necessarily_before/3,      % +A1, +A2, +G
            possibly_between/4,        % +C, +E, +S, +G
            ordering_bit/3,            % +Id, +G, -Bit
            outside_mask/4,            % +E, +S, +G, -Mask
            between_mask/4,            % +E, +S, +G, -Mask
            ancestors_mask/3,          % +Bits, +G, -Mask
            ordering_graph/2,          % +G, -Ugraph
            ordering_arcs/2,           % +G, -PriorTos
            ordering_actions/2,        % +G, -Ids
            linearisation/2,           % +G, -Ids
            linearisation/3,           % +G, :Allowed, -Ids
            linearisation/4            % +G, :Next, +S0, -Ids
          ]).
:- use_module(library(assoc)).
:- use_module(library(ordsets)).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(error)).
:- use_module(library(yall)).
:- use_module(library(pairs), [pairs_keys/2]).

%   The graphs handed out are library(ugraphs) graphs (V-Successors pairs in
%   standard order), built and read here without loading that library: it
%   is not needed to plan, and a cold start would compile it from source.

%!  empty_ordering(-G) is det.
%
%   The ordering graph of the null plan: no actions, no arcs.

empty_ordering(ord(Nodes, Of, 0)) :-
    empty_assoc(Nodes),
    empty_assoc(Of).

%!  ordering_add_action(+Id, +G0, -G) is det.
%
%   Add the node of a new action (Sec. 5.1: "a new node is created in the
%   ordering graph, with the action's action identifier as the node's label").
%   Adding a node that is already there changes nothing.
%
%   @error type_error(atom, Id) if Id is not an atom.

ordering_add_action(Id, G0, G) :-
    must_be(atom, Id),
    add_node(Id, G0, G).

add_node(Id, G0, G) :-
    G0 = ord(Nodes0, Of0, N0),
    (   get_assoc(Id, Nodes0, _)
    ->  G = G0
    ;   put_assoc(Id, Nodes0, n(N0, [], 0, 0), Nodes),
        put_assoc(N0, Of0, Id, Of),
        N is N0 + 1,
        G = ord(Nodes, Of, N)
    ).

%!  prior_to(+A1, +A2, +G0, -G) is semidet.
%
%   Post the constraint prior_to(A1, A2): A1 is executed before A2. Fails,
%   leaving nothing changed, if the constraint is inconsistent with G0, i.e.
%   if A1 == A2 or there is a path from A2 to A1 (Fig. 14). Posting an arc
%   that is already in G0 is a no-op; an action not yet in G0 is added.
%
%   ==
%   ?- empty_ordering(G0), prior_to(a1, a2, G0, G1), \+ prior_to(a2, a1, G1, _).
%   ==
%
%   @error type_error(atom, A) if A1 or A2 is not an atom
%          (instantiation_error if unbound).

prior_to(A1, A2, G0, G) :-
    must_be(atom, A1),
    must_be(atom, A2),
    A1 \== A2,
    prior_to_(A1, A2, G0, G).

prior_to_(start, finish, G, G) :- !.
prior_to_(_, start, _, _) :- !, fail.
prior_to_(finish, _, _, _) :- !, fail.
prior_to_(start, _, G, G) :- !.
prior_to_(_, finish, G, G) :- !.
prior_to_(A1, A2, G0, G) :-
    G0 = ord(Nodes00, _, _),
    (   get_assoc(A1, Nodes00, n(I1, S1, D1, Anc1)),   % both nodes there:
        get_assoc(A2, Nodes00, n(I2, _, D2, _))         % no add_node/3
    ->  G2 = G0
    ;   add_node(A1, G0, G1),
        add_node(A2, G1, G2),
        G2 = ord(Nodes02, _, _),
        get_assoc(A1, Nodes02, n(I1, S1, D1, Anc1)),
        get_assoc(A2, Nodes02, n(I2, _, D2, _))
    ),
    G2 = ord(Nodes0, Of, N),
    D2 /\ (1 << I1) =:= 0,                      % no path A2 -> A1
    (   ord_memberchk(A2, S1)
    ->  G = G2
    ;   ord_add_element(S1, A2, S1a),
        put_assoc(A1, Nodes0, n(I1, S1a, D1, Anc1), Nodes1),
        (   D1 /\ (1 << I2) =\= 0               % implied already
        ->  Nodes = Nodes1
        ;   Up is Anc1 \/ (1 << I1),
            Down is D2 \/ (1 << I2),
            close_arc(Up, Down, Of, N, Nodes1, Nodes)
        ),
        G = ord(Nodes, Of, N)
    ).

%   close_arc(+Up, +Down, +Of, +N, +Nodes0, -Nodes): the closure after an
%   arc from the actions Up (the arc's tail and its ancestors) to the
%   actions Down (its head and its descendants): Down added to the
%   descendants of each of Up, Up to the ancestors of each of Down. When
%   they are many (more than an eighth of the N nodes), in one pass over
%   every node (map_assoc/3: each node visited once, the tree rebuilt
%   once), else node by node (add_bits/6: a look-up and an update each).

close_arc(Up, Down, Of, N, Nodes0, Nodes) :-
    (   8 * (popcount(Up) + popcount(Down)) > N
    ->  map_assoc(close_node(Up, Down), Nodes0, Nodes)
    ;   add_bits(3, Up, Down, Of, Nodes0, Nodes1),
        add_bits(4, Down, Up, Of, Nodes1, Nodes)
    ).

close_node(Up, Down, Node0, Node) :-
    Node0 = n(I, S, D0, A0),
    Bit is 1 << I,
    (   Bit /\ Up =\= 0
    ->  D is D0 \/ Down
    ;   D = D0
    ),
    (   Bit /\ Down =\= 0
    ->  A is A0 \/ Up
    ;   A = A0
    ),
    (   D =:= D0, A =:= A0
    ->  Node = Node0
    ;   Node = n(I, S, D, A)
    ).

%   add_bits(+Field, +Bits, +New, +Of, +Nodes0, -Nodes): New added to the
%   descendants (Field 3 of n(Bit, Succs, Descs, Ancs)) or ancestors (Field
%   4) of every action whose bit is in Bits, lowest first. (A plain
%   recursion over the bits, not a foldl with a closure: a meta-call per
%   node updated.) A node whose set holds the new bits already is left as
%   it is (its assoc path not copied).

add_bits(Field, Bits, New, Of, Nodes0, Nodes) :-
    (   Bits =:= 0
    ->  Nodes = Nodes0
    ;   I is lsb(Bits),
        get_assoc(I, Of, Id),
        get_assoc(Id, Nodes0, Node0),
        arg(Field, Node0, Old),
        (   Old /\ New =:= New
        ->  Nodes1 = Nodes0
        ;   Set is Old \/ New,
            with_field(Field, Node0, Set, Node),
            put_assoc(Id, Nodes0, Node, Nodes1)
        ),
        Bits1 is Bits xor (1 << I),
        add_bits(Field, Bits1, New, Of, Nodes1, Nodes)
    ).

with_field(3, n(I, S, _, A), D, n(I, S, D, A)).
with_field(4, n(I, S, D, _), A, n(I, S, D, A)).

%!  necessarily_before(+A1, +A2, +G) is semidet.
%
%   A1 precedes A2 in every linearisation of G (a path A1 -> A2), counting
%   the virtual start and finish actions. Two look-ups in the closure.

necessarily_before(A1, A2, _) :- A1 == A2, !, fail.
necessarily_before(start, _, _) :- !.
necessarily_before(_, finish, _) :- !.
necessarily_before(_, start, _) :- !, fail.
necessarily_before(finish, _, _) :- !, fail.
necessarily_before(A1, A2, ord(Nodes, _, _)) :-
    get_assoc(A1, Nodes, n(_, _, D1, _)),
    get_assoc(A2, Nodes, n(I2, _, _, _)),
    D1 /\ (1 << I2) =\= 0.

%!  possibly_between(+C, +E, +S, +G) is semidet.
%
%   Action C may be executed after E and before S in some linearisation of
%   G: C is neither E nor S, not necessarily before E and not necessarily
%   after S (the "possible clobberer" test of Sec. 4.1).

possibly_between(C, E, S, G) :-
    C \== E,
    C \== S,
    \+ necessarily_before(C, E, G),
    \+ necessarily_before(S, C, G).

%!  ordering_bit(+Id, +G, -Bit) is semidet.
%
%   Bit is the bitset (1 << I) of the action Id of G, numbered I; fails if
%   Id is not an action of G.

ordering_bit(Id, ord(Nodes, _, _), Bit) :-
    get_assoc(Id, Nodes, n(I, _, _, _)),
    Bit is 1 << I.

%!  outside_mask(+E, +S, +G, -Mask) is det.
%
%   Mask is the bitset of the actions of G that cannot be executed after E
%   and before S: E and its ancestors, S and its descendants (the virtual
%   start and finish add none). An action C of G with ordering_bit(C, G, B)
%   satisfies possibly_between(C, E, S, G) iff B /\ Mask =:= 0: the test
%   of possibly_between/4 for many C at the cost of one.

outside_mask(E, S, G, Mask) :-
    G = ord(Nodes, _, _),
    (   get_assoc(E, Nodes, n(IE, _, _, AncE))
    ->  M1 is AncE \/ (1 << IE)
    ;   M1 = 0
    ),
    (   get_assoc(S, Nodes, n(IS, _, DescS, _))
    ->  Mask is M1 \/ DescS \/ (1 << IS)
    ;   Mask = M1
    ).

%!  between_mask(+E, +S, +G, -Mask) is det.
%
%   Mask is the bitset of the actions of G that necessarily follow E and
%   precede S (the descendants of E that are ancestors of S; every action
%   follows the virtual `start` and precedes `finish`, so
%   between_mask(start, finish, G, -1)). An action C of G with
%   ordering_bit(C, G, B) is necessarily between E and S iff
%   B /\ Mask =\= 0. Mask is 0 if E or S is not an action of G.

between_mask(start, S, G, Mask) :-
    !,
    (   S == finish
    ->  Mask = -1
    ;   G = ord(Nodes, _, _),
        (   get_assoc(S, Nodes, n(_, _, _, Mask))
        ->  true
        ;   Mask = 0
        )
    ).
between_mask(E, finish, ord(Nodes, _, _), Mask) :-
    !,
    (   get_assoc(E, Nodes, n(_, _, Mask, _))
    ->  true
    ;   Mask = 0
    ).
between_mask(E, S, ord(Nodes, _, _), Mask) :-
    (   get_assoc(E, Nodes, n(_, _, DescE, _)),
        get_assoc(S, Nodes, n(_, _, _, AncS))
    ->  Mask is DescE /\ AncS
    ;   Mask = 0
    ).

%!  ancestors_mask(+Bits, +G, -Mask) is det.
%
%   Mask is the bitset of the actions of G that necessarily precede some
%   action whose bit is in Bits (the union of their ancestors; Bits 0
%   gives 0). An action whose ancestors are in Mask already adds nothing
%   (the ancestors of an ancestor are ancestors), so those are skipped:
%   the cost is one look-up per action of Bits that no other of them
%   follows, at most.
%
%   @error type_error(integer, Bits) if Bits is not an integer.

ancestors_mask(Bits, ord(Nodes, Of, _), Mask) :-
    must_be(integer, Bits),
    ancestors_mask_(Bits, Nodes, Of, 0, Mask).

ancestors_mask_(Bits, Nodes, Of, Mask0, Mask) :-
    (   Bits =:= 0
    ->  Mask = Mask0
    ;   I is lsb(Bits),
        get_assoc(I, Of, Id),
        get_assoc(Id, Nodes, n(_, _, _, Anc)),
        Mask1 is Mask0 \/ Anc,
        Bits1 is Bits /\ \ (Anc \/ (1 << I)),
        ancestors_mask_(Bits1, Nodes, Of, Mask1, Mask)
    ).

%!  ordering_graph(+G, -Ugraph) is det.
%
%   The posted arcs of G as a library(ugraphs) graph over its action ids
%   (every action a vertex, arcs as posted, not the closure). A ugraph is
%   returned as it is.

ordering_graph(ord(Nodes, _, _), Ugraph) :-
    !,
    assoc_to_list(Nodes, Pairs),
    maplist([Id-n(_, S, _, _), Id-S]>>true, Pairs, Ugraph).
ordering_graph(Ugraph, Ugraph) :-
    must_be(list, Ugraph).

%!  ordering_arcs(+G, -PriorTos:list) is det.
%
%   The posted arcs of G as prior_to(A1, A2) terms, in standard order.

ordering_arcs(G, PriorTos) :-
    ordering_graph(G, U),
    findall(prior_to(A, B), ( member(A-Bs, U), member(B, Bs) ), PriorTos).

%!  ordering_actions(+G, -Ids:list) is det.
%
%   The action ids of G (its vertices), in standard order.

ordering_actions(G, Ids) :-
    ordering_graph(G, U),
    pairs_keys(U, Ids).

%!  linearisation(+G, -Ids:list) is nondet.
%
%   Ids is a total order of the actions of G consistent with every arc
%   (a topological order). Backtracking enumerates every linearisation
%   once, lazily; sources are tried in standard order.
%
%   ==
%   ?- empty_ordering(G0), foldl(ordering_add_action, [a,b,c], G0, G1),
%      prior_to(a, c, G1, G), findall(L, linearisation(G, L), Ls).
%   Ls = [[a,b,c],[a,c,b],[b,a,c]].
%   ==

linearisation(G, Ids) :-
    linearisation(G, any_next, Ids).

%   any_next(+Done, +V): every action may go next (linearisation/2).
any_next(_, _).

:- meta_predicate linearisation(+, 2, -).

%!  linearisation(+G, :Allowed, -Ids:list) is nondet.
%
%   As linearisation/2, but an action V goes next after the actions Done
%   (in execution order) only if call(Allowed, Done, V) succeeds: a
%   refused prefix cuts every linearisation that starts with it, without
%   enumerating them.

linearisation(G, Allowed, Ids) :-
    linearisation(G, done_allowed(Allowed), [], Ids).

done_allowed(Allowed, V, Done, Done1) :-
    call(Allowed, Done, V),
    append(Done, [V], Done1).

:- meta_predicate linearisation(+, 3, +, -).

%!  linearisation(+G, :Next, +S0, -Ids:list) is nondet.
%
%   As linearisation/2, threading a state through the prefix: an action V
%   goes next in state S0 only if call(Next, V, S0, S) succeeds, and the
%   rest of the order is chosen in state S. A refused V cuts every
%   linearisation whose prefix it would extend (phase 2's instance search,
%   partial_plan.pl, keeps there what each nogood still needs).
%
%   ==
%   ?- empty_ordering(G0), foldl(ordering_add_action, [a,b,c], G0, G),
%      findall(L, linearisation(G, [V, N0, N]>>(N is N0 + 1, (V == c -> N > 1 ; true)),
%                               0, L), Ls).
%   Ls = [[a,b,c],[a,c,b],[b,a,c],[b,c,a]].
%   ==

linearisation(G, Next, S0, Ids) :-
    ordering_graph(G, U),
    predecessors(U, Preds),
    linearise(Preds, Next, S0, Ids).

%   linearise(+Preds, :Next, +S0, -Ids): a source V (no predecessor left,
%   in standard order) that call(Next, V, S0, S) lets go next, then a
%   linearisation of Preds without V from state S.

linearise([], _, _, []) :- !.
linearise(Preds, Next, S0, [V|Vs]) :-
    member(V-[], Preds),
    call(Next, V, S0, S),
    delete_vertex(Preds, V, Preds1),
    linearise(Preds1, Next, S, Vs).

%   predecessors(+Ugraph, -Preds): Preds is Ugraph transposed, V-Ps pairs
%   in standard order, Ps the ordset of the vertices with an arc to V.

predecessors(U, Preds) :-
    findall(B-A, ( member(A-Bs, U), member(B, Bs) ), Arcs0),
    msort(Arcs0, Arcs),
    pairs_keys(U, Vs),
    predecessors_(Vs, Arcs, Preds).

predecessors_([], _, []).
predecessors_([V|Vs], Arcs0, [V-Ps|Preds]) :-
    take_key(Arcs0, V, Ps, Arcs),
    predecessors_(Vs, Arcs, Preds).

take_key([K-X|Arcs0], V, [X|Xs], Arcs) :-
    K == V,
    !,
    take_key(Arcs0, V, Xs, Arcs).
take_key(Arcs, _, [], Arcs).

delete_vertex([], _, []).
delete_vertex([W-Ps0|Preds0], V, Preds) :-
    (   W == V
    ->  delete_vertex(Preds0, V, Preds)
    ;   ord_del_element(Ps0, V, Ps),
        Preds = [W-Ps|Preds1],
        delete_vertex(Preds0, V, Preds1)
    ).
