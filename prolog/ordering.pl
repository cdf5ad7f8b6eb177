/*  spar-py: the ordering graph of phase 1 (Sec. 5.1, Fig. 14).

    Ordering constraints prior_to(Action1, Action2) are the arcs of a directed
    graph over the plan's action ids, kept as a library(ugraphs) graph and
    threaded through the planner (G0 -> G). A constraint is refused when it
    would close a cycle, that is when there is already a path from Action2 to
    Action1.

    Two virtual actions bound every plan and are never stored: `start`, the
    null action whose add list is the initial state (Sec. 7.1), precedes every
    action; `finish`, at which the user's goals must hold, follows every
    action. So prior_to(start, A) and prior_to(A, finish) always hold and add
    no arc, while prior_to(A, start) and prior_to(finish, A) are refused.
*/
:- module(ordering,
          [ empty_ordering/1,          % -G
            ordering_add_action/3,     % +Id, +G0, -G
            prior_to/4,                % +A1, +A2, +G0, -G
            necessarily_before/3,      % +A1, +A2, +G
            possibly_between/4,        % +C, +E, +S, +G
            ordering_arcs/2,           % +G, -PriorTos
            ordering_actions/2,        % +G, -Ids
            linearisation/2            % +G, -Ids
          ]).
:- use_module(library(ugraphs)).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(error)).
:- use_module(library(yall)).

%!  empty_ordering(-G) is det.
%
%   The ordering graph of the null plan: no actions, no arcs.

empty_ordering([]).

%!  ordering_add_action(+Id, +G0, -G) is det.
%
%   Add the node of a new action (Sec. 5.1: "a new node is created in the
%   ordering graph, with the action's action identifier as the node's label").
%
%   @error type_error(atom, Id) if Id is not an atom.

ordering_add_action(Id, G0, G) :-
    must_be(atom, Id),
    add_vertices(G0, [Id], G).

%!  prior_to(+A1, +A2, +G0, -G) is semidet.
%
%   Post the constraint prior_to(A1, A2): A1 is executed before A2. Fails,
%   leaving nothing changed, if the constraint is inconsistent with G0, i.e.
%   if A1 == A2 or there is a path from A2 to A1 (Fig. 14). Posting an arc
%   that is already in G0 is a no-op.
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
    \+ path(A2, A1, G0),
    add_edges(G0, [A1-A2], G).

%!  path(+From, +To, +G) is semidet.
%
%   There is a non-empty path From -> ... -> To in G.

path(From, To, G) :-
    neighbours_(From, G, Ns),
    path_dfs(Ns, To, G, [From]).

path_dfs([V|Vs], To, G, Seen) :-
    (   V == To
    ->  true
    ;   memberchk(V, Seen)
    ->  path_dfs(Vs, To, G, Seen)
    ;   neighbours_(V, G, Ns),
        append(Ns, Vs, Stack),
        path_dfs(Stack, To, G, [V|Seen])
    ).

neighbours_(V, G, Ns) :-
    (   memberchk(V-Ns0, G) -> Ns = Ns0 ; Ns = [] ).

%!  necessarily_before(+A1, +A2, +G) is semidet.
%
%   A1 precedes A2 in every linearisation of G (a path A1 -> A2), counting
%   the virtual start and finish actions.

necessarily_before(A1, A2, _) :- A1 == A2, !, fail.
necessarily_before(start, _, _) :- !.
necessarily_before(_, finish, _) :- !.
necessarily_before(_, start, _) :- !, fail.
necessarily_before(finish, _, _) :- !, fail.
necessarily_before(A1, A2, G) :-
    path(A1, A2, G).

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

%!  ordering_arcs(+G, -PriorTos:list) is det.
%
%   The posted arcs of G as prior_to(A1, A2) terms, in standard order.

ordering_arcs(G, PriorTos) :-
    edges(G, Edges),
    maplist([A-B, prior_to(A, B)]>>true, Edges, PriorTos).

%!  ordering_actions(+G, -Ids:list) is det.
%
%   The action ids of G (its vertices), in standard order.

ordering_actions(G, Ids) :-
    vertices(G, Ids).

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
    transpose_ugraph(G, Preds),
    linearise(Preds, Ids).

linearise([], []) :- !.
linearise(Preds, [V|Vs]) :-
    member(V-[], Preds),
    del_vertices(Preds, [V], Preds1),
    linearise(Preds1, Vs).
