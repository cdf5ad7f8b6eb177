/*  spar-py: satisfying operational goals (Sec. 4.1): establishment,
    clobbering, promotion, separation and white knights.

    establish/4 finds an action E whose add list has an element unifying
    with the goal's condition and posts prior_to(E, S) (nothing to post for
    `start`, which precedes every action), trying in order

      1. the actions already in the plan, newest first (constraint posting
         before adding actions, Sec. 2),
      2. the initial state, the add list of the null action `start`
         (Sec. 7.1); a position it names gets its single label in the CMS,
      3. a new action from the rule base (kb/templates/spar_actions.pl).

    declobber/4 then deals with every action C that may clobber the goal:
    C has a delete-list element unifiable with the condition (tested
    without binding anything) and may fall between E and S. The methods
    are a table tried in the order of the plan's methods (option
    declobber, by default [promotion, separation, white_knight] as
    spar_defaults.pl says; [promotion, white_knight] is the paper's
    planner):

      promotion     prior_to(S, C)
      separation    dif(D, Cond) for every delete-list element D of C that
                    unifies with the condition (Sec. 4.1, Chapman's
                    separation; not in SPAR): C then cannot clobber it,
                    whatever the still unbound variables of D become
      white_knight  an action W, existing or new, that establishes the
                    condition, with prior_to(C, W) and prior_to(W, S)
                    (W = E is the establisher acting as its own white
                    knight, Sec. 4.1)

    If C must fall between E and S, only separation is tried: promotion
    would close a cycle, and a white knight between C and S is the same
    plan as establishing the goal by it directly, with fewer orderings,
    which establish/4 tries among its alternatives.

    Why this order: promotion adds one ordering and binds nothing, and is
    the paper's first choice; separation adds neither an action nor an
    ordering, but it commits a variable of C away from a value (C's own
    precondition must later be established by something else, which may
    cost actions), so it comes after promotion; a white knight adds an
    action or orderings and comes last. A separation is a constraint
    posted with dif/2 on the plan's terms (attributed variables: it lives
    in the threaded plan state and backtracking removes it) and is also
    recorded as sep(D, Cond) in the plan state (plan_state.pl), since a dif/2
    between two terms that become different atoms vanishes: plan
    instances (spar:partial_instances/2) must keep D and Cond different
    after the network variables get their labels.

    add_action/5 is the one place an action enters the plan: it posts the
    action's initial constraints and ordering arcs, pushes its
    preconditions and moves back to the operational stack every satisfied
    goal the action could clobber (Sec. 2).
*/
:- module(establish,
          [ establish/4,               % +Goal, +Plan0, -Plan, -Establisher
            establish/5,               % +Goal, +Cands, +Plan0, -Plan, -Establisher
            declobber/4,               % +Goal, +Establisher, +Plan0, -Plan
            declobber/5,               % +Goal, +Establisher, +Cands, +Plan0, -Plan
            clobber_candidates/3,      % +Goal, +Plan, -Cands
            new_action/5,              % +Cond, -Id, +Arcs, +Plan0, -Plan
            add_action/5,              % +Action, +Cs, +Arcs, +Plan0, -Plan
            post_prior_to/4,           % +A1, +A2, +Plan0, -Plan
            post_precedence/3,         % +Action, +Plan0, -Plan
            possible_clobberer/5,      % +Cond, +E, +S, +Plan, -C
            known_declobber_method/1   % ?Method
          ]).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(error)).
:- use_module(library(assoc)).
:- use_module(library(dif)).     % imported, not autoloaded: autoloading reads the library index

:- use_module(kb, []).
:- use_module(ordering).
:- use_module(cms).
:- use_module(plan_state).
:- use_module(spar_paths, []).    % the file search path spar
:- use_module(spar(kb/templates/spar_actions), [instantiate_establishing_action//3]).

%!  establish(+Goal, +Plan0, -Plan, -Establisher) is nondet.
%
%   Goal = op(Id, S, Cond) holds before S because of Establisher (an action
%   id, or `start` for the initial state), constrained to precede S.
%   Alternatives on backtracking, in the order of the module header.

establish(op(_, S, Cond), Plan0, Plan, E) :-
    establish_(Cond, S, none, Plan0, Plan, E).

%!  establish(+Goal, +Cands, +Plan0, -Plan, -Establisher) is nondet.
%
%   establish/4 without the establishers that no declobbering can save:
%   an existing action or `start` is skipped when some plan action C
%   necessarily falls between it and S and deletes a term identical to
%   the condition (as the establisher binds it). Promotion of C would
%   close a cycle, a white knight is not tried for C (declobber/5), and
%   separation, the only remedy left, posts dif/2 between identical terms
%   and fails. Orderings and bindings are only ever added, so C stays
%   between and identical on every extension of the plan: declobber/5
%   fails for that establisher on every branch. Skipping it before its
%   arc is posted gives the same solutions in the same order, without
%   the work (at N = 50 generated parts, 80,000 such establishers per
%   plan). Cands are the goal's candidates (clobber_candidates/3, from
%   Plan0).

establish(op(_, S, Cond), cands(_, Cs, _, Ident), Plan0, Plan, E) :-
    (   ground(Cond)
    ->  plan_order(Plan0, G),
        between_mask(start, S, G, Before),
        Bits is Ident /\ Before,          % the identical ones before S
        ancestors_mask(Bits, G, Anc),     % the actions before one of them
        Doom = bits(Bits, Anc)
    ;   Doom = doom(Cs)
    ),
    establish_(Cond, S, Doom, Plan0, Plan, E).

%   establish_(+Cond, +S, +Doom, +Plan0, -Plan, -E): the alternatives of
%   establish/4; Doom is none (try every establisher) or what doomed/5
%   needs to skip the doomed ones.

establish_(Cond, S, Doom, Plan0, Plan, E) :-
    (   existing_establisher(Cond, S, Doom, Plan0, Plan, E)
    ;   initial_establisher(Cond, S, Doom, Plan0, Plan),
        E = start
    ;   new_action(Cond, E, [E-S], Plan0, Plan)
    ),
    note(Plan, "  ~q established by ~q~n", [Cond, E]).

existing_establisher(Cond, S, Doom, Plan0, Plan, E) :-
    (   Doom = bits(_, Skip)            % doomed iff its bit is in Skip
    ->  true
    ;   Skip = 0
    ),
    plan_adder(Cond, Plan0, S, Skip, E, Adds),
    member(Cond, Adds),
    \+ doomed(Doom, Cond, E, S, Plan0),
    post_prior_to(E, S, Plan0, Plan).

initial_establisher(Cond, S, Doom, Plan0, Plan) :-
    kb:initial(Cond),
    \+ doomed(Doom, Cond, start, S, Plan0),
    plan_net(Plan0, Net0),
    cms_initial_state(Cond, Net0, Net),
    set_net_of_plan(Net, Plan0, Plan).

%   doomed(+Doom, +Cond, +E, +S, +Plan): a candidate necessarily between
%   E and S deletes a term identical to Cond (see establish/5). Doom is
%   none (nothing is doomed), or, for a Cond ground as listed (it cannot
%   change then), bits(Bits, Anc), Bits the bitset of the candidates with
%   such a term that necessarily precede S and Anc the actions that
%   necessarily precede one of them (ordering:ancestors_mask/3): E is
%   doomed iff it is `start` and Bits is not empty, or its bit is in Anc
%   (one of them is a descendant of E); else doom(Cs), and the candidates
%   of Cs between E and S are looked at. Posting E -> S leaves the actions
%   between E and S as they were (a new path through E -> S from E to some
%   C would go on to S's descendants, after S), so the test may come
%   before the arc. existing_establisher/6 skips the plan actions doomed
%   by bits(_, Anc) before trying their add lists (plan_adder/6): the test
%   does not depend on what the add list binds.

doomed(none, _, _, _, _) :-
    !,
    fail.
doomed(bits(Bits, Anc), _, E, _, Plan) :-
    !,
    Bits =\= 0,
    (   E == start
    ->  true
    ;   plan_order(Plan, G),
        ordering_bit(E, G, Bit),
        Bit /\ Anc =\= 0
    ).
doomed(doom(Cs), Cond, E, S, Plan) :-
    plan_order(Plan, G),
    between_mask(E, S, G, Between),
    Between =\= 0,
    member(c(_, Bit, Dels), Cs),
    Bit /\ Between =\= 0,
    identical_member(Cond, Dels),
    !.

%   identical_bits(+Cs, +Cond, +Bits0, -Bits): Bits0 with the bits of the
%   candidates c(Id, Bit, Dels) of Cs with a delete-list element == Cond.

identical_bits([], _, Bits, Bits).
identical_bits([c(_, Bit, Dels)|Cs], Cond, Bits0, Bits) :-
    (   identical_member(Cond, Dels)
    ->  Bits1 is Bits0 \/ Bit
    ;   Bits1 = Bits0
    ),
    identical_bits(Cs, Cond, Bits1, Bits).

identical_member(X, [Y|Ys]) :-
    (   X == Y
    ->  true
    ;   identical_member(X, Ys)
    ).

%!  post_prior_to(+A1, +A2, +Plan0, -Plan) is semidet.
%
%   Post prior_to(A1, A2) in the ordering graph; fails if it closes a cycle.

post_prior_to(A1, A2, Plan0, Plan) :-
    plan_order(Plan0, G0),
    prior_to(A1, A2, G0, G),
    set_order_of_plan(G, Plan0, Plan).

%!  post_precedence(+Action, +Plan0, -Plan) is semidet.
%
%   Post the orderings the product's geometry forces between Action and
%   the assembles already in the plan: for an assemble of part P and one
%   of part Q, prior_to(A_P, A_Q) when kb:precedence(P, Q, _) (Q in place
%   would block P's insertion; world/product/products.py), and the converse. Fails
%   if an ordering closes a cycle. Nothing for other actions, or where the
%   cell has no product.
%
%   @error type_error(action, Action) if Action is not an action/5 term.

post_precedence(Action, Plan0, Plan) :-
    must_be(compound, Action),
    (   Action = action(Id, Term, _, _, _)
    ->  true
    ;   type_error(action, Action)
    ),
    (   Term = assemble(P, _, _, _, _)
    ->  plan_actions(Plan0, Actions),
        foldl(precede(Id, P), Actions, Plan0, Plan)
    ;   Plan = Plan0
    ).

%   precede(+Id, +P, +Other, +Plan0, -Plan): the orderings between the
%   assemble Id of part P and Other (an action of the plan).

precede(Id, P, action(Id2, Term, _, _, _), Plan0, Plan) :-
    (   Id2 \== Id,
        Term = assemble(Q, _, _, _, _)
    ->  (   kb:precedence(P, Q, _)
        ->  post_prior_to(Id, Id2, Plan0, Plan1),
            note(Plan1, "  precedence: prior_to(~q, ~q)~n", [Id, Id2])
        ;   Plan1 = Plan0
        ),
        (   kb:precedence(Q, P, _)
        ->  post_prior_to(Id2, Id, Plan1, Plan),
            note(Plan, "  precedence: prior_to(~q, ~q)~n", [Id2, Id])
        ;   Plan = Plan1
        )
    ;   Plan = Plan0
    ).

%!  new_action(+Cond, -Id, +Arcs, +Plan0, -Plan) is nondet.
%
%   Add a new action Id from the rule base that establishes Cond, posting
%   Arcs (A1-A2 pairs that may mention Id). Fails when the plan has as many
%   actions as its bound allows.

new_action(Cond, Id, Arcs, Plan0, Plan) :-
    plan_ids(Plan0, Ids0),
    call_dcg(instantiate_establishing_action(Cond, Action, Constraints),
             Ids0, Ids),
    Action = action(Id, _, _, addlist(Adds), _),
    memberchk(Cond, Adds),
    room_for_action(Plan0),
    set_ids_of_plan(Ids, Plan0, Plan1),
    add_action(Action, Constraints, Arcs, Plan1, Plan).

room_for_action(Plan) :-
    plan_actions(Plan, Actions),
    plan_bound(Plan, Bound),
    length(Actions, N),
    (   N < Bound
    ->  true
    ;   note(Plan, "  no new action: the plan has ~d, the bound~n", [N]),
        bound_hit(Plan),
        fail
    ).

%!  add_action(+Action, +Constraints, +Arcs, +Plan0, -Plan) is semidet.
%
%   Put Action (an instantiated template) into the plan: its node in the
%   ordering graph, the arcs Arcs, its initial constraints (Sec. 3.1), its
%   preconditions on the goal stacks, and, on top of the operational stack,
%   every satisfied goal it could clobber (Sec. 2, 4.1). Fails if an arc
%   or a constraint on an existing node is refused.

add_action(Action, Constraints, Arcs, Plan0, Plan) :-
    Action = action(Id, Term, preconditions(Ops, Geos), _, _),
    plan_actions(Plan0, Actions),
    set_actions_of_plan([Action|Actions], Plan0, Plan1),
    plan_order(Plan1, G0),
    ordering_add_action(Id, G0, G1),
    index_action(Action, G1, Plan1, Plan1a),
    set_order_of_plan(G1, Plan1a, Plan2),
    foldl([A1-A2, P0, P]>>post_prior_to(A1, A2, P0, P), Arcs, Plan2, Plan2a),
    post_precedence(Action, Plan2a, Plan3),
    plan_net(Plan3, Net0),
    foldl(cms_initial, Constraints, Net0, Net),
    set_net_of_plan(Net, Plan3, Plan4),
    note(Plan4, "  new action(~q, ~q)~n", [Id, Term]),
    undone_goals(Action, Plan4, Undone, Sat),
    set_sat_of_plan(Sat, Plan4, Plan5),
    forall(member(G, Undone), note(Plan5, "  may be clobbered: ~q~n", [G])),
    plan_ops(Plan5, Ops0),
    append(Ops, Ops0, Ops1),
    append(Undone, Ops1, Ops2),
    set_ops_of_plan(Ops2, Plan5, Plan6),
    plan_geos(Plan6, Geos0),
    append(Geos, Geos0, Geos1),
    set_geos_of_plan(Geos1, Plan6, Plan).

                 /*******************************
                 *   THE ADD AND DELETE INDEX   *
                 *******************************/

%   The plan state indexes its actions by the terms of their add and
%   delete lists (plan_state:plan_index/2): index(Adds, Dels), each an
%   assoc from a term key to b(Bits, Entries): Entries the actions with a
%   term of that key, c(Id, Bit, Terms) newest first (Terms the whole add
%   or delete list), Bits the union of their bits (so that the bits of a
%   key's actions cost no walk of its list).
%   A term's key is k(F, A, X) for a compound F/A whose first argument X
%   is atomic, k(F, A) for one whose first argument is not (a variable
%   now, which may be bound later, or a compound), k(T, 0) for an atomic
%   term T and `any` for a variable. A term unifying with a condition
%   whose first argument X is atomic (or an atomic condition) is under
%   the condition's own key, under k(F, A) or under `any`: the actions
%   under those three keys, merged newest first, are a superset of the
%   actions with a term unifying with the condition, in the order of the
%   plan's action list. A condition of another shape is looked up in the
%   whole list. Keys only ever get more precise by binding (a variable
%   first argument bound later leaves its action under k(F, A), which is
%   still looked at), so the index stays a superset on every extension.

term_key(T, Key) :-
    (   var(T)
    ->  Key = any
    ;   compound(T)
    ->  compound_name_arity(T, F, A),
        (   A > 0, arg(1, T, X), atomic(X)
        ->  Key = k(F, A, X)
        ;   Key = k(F, A)
        )
    ;   Key = k(T, 0)
    ).

%   index_action(+Action, +G, +Plan0, -Plan): Action (numbered in the
%   ordering G) entered in the index under the keys of its add and delete
%   lists, once per key.

index_action(action(Id, _, _, addlist(Adds), dellist(Dels)), G, Plan0, Plan) :-
    ordering_bit(Id, G, Bit),
    plan_index(Plan0, index(AddIx0, DelIx0)),
    index_terms(Adds, c(Id, Bit, Adds), AddIx0, AddIx),
    index_terms(Dels, c(Id, Bit, Dels), DelIx0, DelIx),
    set_index_of_plan(index(AddIx, DelIx), Plan0, Plan).

index_terms(Terms, Entry, Ix0, Ix) :-
    maplist(term_key, Terms, Keys0),
    sort(Keys0, Keys),
    foldl(index_entry(Entry), Keys, Ix0, Ix).

index_entry(Entry, Key, Ix0, Ix) :-
    Entry = c(_, Bit, _),
    (   get_assoc(Key, Ix0, b(Bits0, Es))
    ->  Bits is Bits0 \/ Bit
    ;   Bits = Bit,
        Es = []
    ),
    put_assoc(Key, Ix0, b(Bits, [Entry|Es]), Ix).

%   indexed(+Cond, +Which, +Plan, -Entries) is semidet: the entries
%   c(Id, Bit, Terms), newest first, of the actions whose add (Which =
%   adds) or delete (dels) list may have a term unifying with Cond; fails
%   if Cond's shape is not one the index answers (see above).

indexed(Cond, Which, Plan, Entries) :-
    indexed(Cond, Which, Plan, _-Own, Others, _),
    merge_entries(Own, Others, Entries).

%   indexed(+Cond, +Which, +Plan, -OwnBits-Own, -Others, -Decides) is
%   semidet: indexed/4's entries in two lists, newest first: Own those
%   under Cond's own key (OwnBits the union of their bits), Others those
%   under k(F, A) or `any` (an action under both is in both). Decides is
%   true if Cond's key decides unification: Cond is an atom, or F(X) with
%   X atomic, so every term under its key (k(T, 0) is T, k(F, 1, X) is
%   F(X): keys only get more precise by binding) is Cond itself; else
%   false.

indexed(Cond, Which, Plan, OwnBits-Own, Others, Decides) :-
    nonvar(Cond),
    (   compound(Cond)
    ->  compound_name_arity(Cond, F, A),
        A > 0,
        arg(1, Cond, X),
        atomic(X),
        Key = k(F, A, X),
        Wide = k(F, A),
        (   A =:= 1 -> Decides = true ; Decides = false )
    ;   Key = k(Cond, 0),
        Wide = none,
        Decides = true
    ),
    plan_index(Plan, Index),
    (   Which == adds -> arg(1, Index, Ix) ; arg(2, Index, Ix) ),
    bucket(Key, Ix, OwnBits, Own),
    bucket(Wide, Ix, _, Es2),
    bucket(any, Ix, _, Es3),
    merge_entries(Es2, Es3, Others).

%   bucket(+Key, +Ix, -Bits, -Entries): the entries of the index Ix under
%   Key, newest first, and the union of their bits (0 and [] if none).

bucket(Key, Ix, Bits, Es) :-
    (   get_assoc(Key, Ix, b(Bits0, Es0))
    ->  Bits = Bits0,
        Es = Es0
    ;   Bits = 0,
        Es = []
    ).

%   merge_entries(+Es1, +Es2, -Es): two lists of entries by decreasing
%   bit merged, an entry in both kept once.

merge_entries([], Es, Es) :- !.
merge_entries(Es, [], Es) :- !.
merge_entries([E1|Es1], [E2|Es2], Es) :-
    E1 = c(_, B1, _),
    E2 = c(_, B2, _),
    (   B1 > B2
    ->  Es = [E1|Es0],
        merge_entries(Es1, [E2|Es2], Es0)
    ;   B2 > B1
    ->  Es = [E2|Es0],
        merge_entries([E1|Es1], Es2, Es0)
    ;   Es = [E1|Es0],
        merge_entries(Es1, Es2, Es0)
    ).

%   plan_adder(+Cond, +Plan, -Id, -Adds) is nondet: the actions of Plan,
%   newest first, that may establish Cond (Adds their add lists): those
%   the index lists for Cond, or all of them.

plan_adder(Cond, Plan, Id, Adds) :-
    (   indexed(Cond, adds, Plan, Entries)
    ->  member(c(Id, _, Adds), Entries)
    ;   plan_actions(Plan, Actions),
        member(action(Id, _, _, addlist(Adds), _), Actions)
    ).

%   plan_adder(+Cond, +Plan, +S, +Skip, -Id, -Adds) is nondet:
%   plan_adder/4's actions but S and those whose bit is in the bitset
%   Skip, in the same order; the skipped ones are passed over without a
%   choice point each.

plan_adder(Cond, Plan, S, Skip, Id, Adds) :-
    (   indexed(Cond, adds, Plan, Entries)
    ->  next_adder(Entries, S, Skip, Id, Adds)
    ;   plan_actions(Plan, Actions),
        plan_order(Plan, G),
        member(action(Id, _, _, addlist(Adds), _), Actions),
        Id \== S,
        \+ ( Skip =\= 0,
             ordering_bit(Id, G, Bit),
             Bit /\ Skip =\= 0 )
    ).

next_adder([c(Id0, Bit, Adds0)|Es], S, Skip, Id, Adds) :-
    (   ( Id0 == S ; Bit /\ Skip =\= 0 )
    ->  next_adder(Es, S, Skip, Id, Adds)
    ;   (   Id = Id0,
            Adds = Adds0
        ;   next_adder(Es, S, Skip, Id, Adds)
        )
    ).

%   undone_goals(+Action, +Plan, -Undone, -Sat): the satisfied operational
%   goals Action could clobber, and the satisfied list without them.

undone_goals(action(Id, _, _, _, dellist(Dels)), Plan, Undone, Sat) :-
    plan_sat(Plan, Sat0),
    plan_order(Plan, G),
    undone_goals_(Sat0, Id, Dels, G, Undone, Sat).

%   undone_goals_(+Sat0, +C, +Dels, +G, -Undone, -Sat): a plain recursion
%   (partition/4 would make a meta-call per satisfied goal for every new
%   action), the order of Sat0 kept in both lists.

undone_goals_([], _, _, _, [], []).
undone_goals_([Entry|Sat0], C, Dels, G, Undone, Sat) :-
    (   undone_by(C, Dels, G, Entry)
    ->  Entry = sat(Goal, _),
        Undone = [Goal|Undone1],
        Sat = Sat1
    ;   Undone = Undone1,
        Sat = [Entry|Sat1]
    ),
    undone_goals_(Sat0, C, Dels, G, Undone1, Sat1).

undone_by(C, Dels, G, sat(op(_, S, Cond), E)) :-
    clobbers(Dels, Cond),
    possibly_between(C, E, S, G).

clobbers([D|Ds], Cond) :-               % a loop, not member/2: no choice
    (   \+ D \= Cond                      % point left at each element
    ->  true
    ;   clobbers(Ds, Cond)
    ).

%!  possible_clobberer(+Cond, +E, +S, +Plan, -C) is nondet.
%
%   C is a plan action that may clobber Cond between its establisher E and
%   S: a delete-list element unifies with Cond (nothing is bound) and C may
%   be executed after E and before S.

possible_clobberer(Cond, E, S, Plan, C) :-
    plan_actions(Plan, Actions),
    plan_order(Plan, G),
    member(action(C, _, _, _, dellist(Dels)), Actions),
    clobbers(Dels, Cond),
    possibly_between(C, E, S, G).

%!  known_declobber_method(?Method) is nondet.
%
%   The declobbering methods declobber_by/7 implements.

known_declobber_method(promotion).
known_declobber_method(separation).
known_declobber_method(white_knight).

%!  declobber(+Goal, +Establisher, +Plan0, -Plan) is nondet.
%
%   Plan makes Goal = op(Id, S, Cond), established by Establisher, safe
%   from every possible clobberer (Sec. 4.1, the truth criterion of
%   Sec. 7.1): each is dealt with by one of the plan's declobbering
%   methods, tried in order (by separation only, if it necessarily falls
%   between Establisher and S: see necessarily_between/4). Clobberers are
%   taken one at a time, newest first, each the first possible clobberer
%   of the plan as it is then, so actions added by a white knight are
%   considered too.
%
%   The possible clobberers are found incrementally: the actions whose
%   delete lists unify with the condition are listed once per goal
%   (clobber_candidates/3, shared by all the goal's establishers), then
%   scanned once, lazily, newest first, each tested against a bitset of
%   the actions that cannot fall between E and S (ordering:outside_mask/4);
%   after each remedy only the actions it added are listed before the scan
%   goes on where it stopped.
%   Being a possible clobberer only ever stops on a branch (orderings,
%   bindings and separations are only added), so an action the scan passed
%   never becomes one, and the clobberers come in the order a fresh scan of
%   the whole plan would find them.

declobber(Goal, E, Plan0, Plan) :-
    clobber_candidates(Goal, Plan0, Cands),
    declobber(Goal, E, Cands, Plan0, Plan).

%!  clobber_candidates(+Goal, +Plan, -Cands) is det.
%
%   Cands lists, newest first, the actions of Plan that may clobber the
%   condition of Goal = op(Id, S, Cond) whatever its establisher: those
%   with a delete-list element unifying with Cond (nothing is bound), each
%   as c(Id, Bit, Dels), Bit its bit in the ordering (ordering_bit/3),
%   in cands(Actions, List, Bits, Ident) with the plan's actions, the
%   union of the bits and, for a ground Cond, the union of the bits of
%   those with a delete-list element == Cond (`none` for a Cond not
%   ground; establish/5 skips the establishers they doom). The bits fall
%   along the list: a newer action has a higher number in the ordering.
%   Computed once for a goal, they serve every establisher tried for it
%   (declobber/5): the unification test does not depend on the
%   establisher, and binding Cond or separating only shortens the list.
%   Under a key that decides unification (indexed/6) every action deletes
%   Cond itself: the key's bits are both Bits and Ident, with no walk of
%   its actions.

clobber_candidates(op(_, _, Cond), Plan, cands(Actions, Cands, Bits, Ident)) :-
    plan_actions(Plan, Actions),
    (   indexed(Cond, dels, Plan, OwnBits-Own, Others, Decides)
    ->  (   Decides == true             % each of Own deletes Cond itself:
        ->  indexed_candidates(Others, Cond, Cands2, OwnBits, Bits),
            merge_entries(Own, Cands2, Cands),
            identical_bits(Cands2, Cond, OwnBits, Ident)
        ;   merge_entries(Own, Others, Entries),
            indexed_candidates(Entries, Cond, Cands, 0, Bits),
            ground_identical_bits(Cond, Cands, Ident)
        )
    ;   plan_order(Plan, G),
        clobber_candidates_(Actions, Cond, G, Cands, 0, Bits),
        ground_identical_bits(Cond, Cands, Ident)
    ).

%   ground_identical_bits(+Cond, +Cands, -Ident): the bits of the
%   candidates with a delete-list element == Cond if Cond is ground, else
%   `none`.

ground_identical_bits(Cond, Cands, Ident) :-
    (   ground(Cond)
    ->  identical_bits(Cands, Cond, 0, Ident)
    ;   Ident = none
    ).

%   indexed_candidates(+Entries, +Cond, -Cands, +Bits0, -Bits): the
%   entries c(Id, Bit, Dels) of Entries (from the index, newest first)
%   with a delete-list element unifying with Cond; Bits is Bits0 with
%   their bits set.

indexed_candidates([], _, [], Bits, Bits).
indexed_candidates([E|Es], Cond, Cs, Bits0, Bits) :-
    E = c(_, Bit, Dels),
    (   clobbers(Dels, Cond)
    ->  Cs = [E|Cs1],
        Bits1 is Bits0 \/ Bit
    ;   Cs = Cs1,
        Bits1 = Bits0
    ),
    indexed_candidates(Es, Cond, Cs1, Bits1, Bits).

%   clobber_candidates_(+Actions, +Cond, +G, -Cands, +Bits0, -Bits): Bits
%   is Bits0 with the bits of Cands set.

clobber_candidates_([], _, _, [], Bits, Bits).
clobber_candidates_([action(C, _, _, _, dellist(Dels))|As], Cond, G, Cs, Bits0, Bits) :-
    (   clobbers(Dels, Cond),
        ordering_bit(C, G, Bit)
    ->  Cs = [c(C, Bit, Dels)|Cs1],
        Bits1 is Bits0 \/ Bit
    ;   Cs = Cs1,
        Bits1 = Bits0
    ),
    clobber_candidates_(As, Cond, G, Cs1, Bits1, Bits).

%!  declobber(+Goal, +Establisher, +Cands, +Plan0, -Plan) is nondet.
%
%   declobber/4 with the candidates of clobber_candidates/3, computed from
%   Plan0 or an earlier plan of the same branch (the actions added since
%   are examined too).

declobber(op(_, S, Cond), E, cands(Seen, Cands, Bits, _), Plan0, Plan) :-
    plan_methods(Plan0, Methods),
    declobber_(Cands, Bits, Seen, Cond, E, S, Methods, Plan0, Plan).

%   declobber_(+Todo, +Bits, +Seen, +Cond, +E, +S, +Methods, +Plan0, -Plan):
%   Todo the candidates c(Id, Bit, Dels) from Seen (the plan's actions
%   when they were listed) not scanned yet, Bits the union of their bits;
%   the actions Plan0 has beyond Seen come first.

declobber_(Todo0, Bits0, Seen, Cond, E, S, Methods, Plan0, Plan) :-
    plan_actions(Plan0, Actions),
    plan_order(Plan0, G),
    added_since(Actions, Seen, New),
    clobber_candidates_(New, Cond, G, Todo1, Bits0, Bits),
    append(Todo1, Todo0, Todo),
    outside_mask(E, S, G, Mask),
    Possible is Bits /\ \ Mask,
    (   next_clobberer(Possible, Todo, Cond, C, BitC, Rest)
    ->  (   necessarily_between(C, E, S, Plan0)
        ->  memberchk(separation, Methods),
            Method = separation
        ;   member(Method, Methods)
        ),
        declobber_by(Method, Cond, E, S, C, Plan0, Plan1),
        RestBits is Bits /\ (BitC - 1),
        declobber_(Rest, RestBits, Actions, Cond, E, S, Methods, Plan1, Plan)
    ;   Plan = Plan0
    ).

%   next_clobberer(+Possible, +Cands, +Cond, -C, -Bit, -Rest): C (bit Bit)
%   the first of Cands whose bit is in Possible (it may fall between the
%   establisher and S: ordering:outside_mask/4) and that still has a
%   delete-list element unifying with Cond; Rest the candidates after it.
%   The candidates' bits decrease along the list, so the next one to test
%   is the highest bit of Possible, and none is left when it is 0.

next_clobberer(Possible, Cands, Cond, C, BitC, Rest) :-
    Possible =\= 0,
    Top is 1 << msb(Possible),
    skip_to(Cands, Top, c(C0, _, Dels), Cs),
    (   clobbers(Dels, Cond)
    ->  C = C0,
        BitC = Top,
        Rest = Cs
    ;   Possible1 is Possible xor Top,
        next_clobberer(Possible1, Cs, Cond, C, BitC, Rest)
    ).

skip_to([X|Xs], Top, Y, Rest) :-
    X = c(_, Bit, _),
    (   Bit =:= Top
    ->  Y = X,
        Rest = Xs
    ;   skip_to(Xs, Top, Y, Rest)
    ).

%   added_since(+Actions, +Seen, -New): the actions of Actions before its
%   suffix Seen (the plan's actions are kept newest first).

added_since(Actions, Seen, New) :-
    (   Actions == Seen
    ->  New = []
    ;   length(Actions, N),
        length(Seen, N0),
        K is N - N0,
        length(New, K),
        append(New, _, Actions)
    ).

%   necessarily_between(+C, +E, +S, +Plan): C follows E and precedes S
%   in every linearisation. Then promotion closes a cycle, and of the white
%   knights only one W between C and S can save the goal; establishing it
%   by W directly (W acting as its own white knight for C) gives the same
%   actions and a weaker ordering; that alternative is tried as an
%   establishment, so this one is dropped. Separation alone remains.

necessarily_between(C, E, S, Plan) :-
    plan_order(Plan, G),
    necessarily_before(E, C, G),
    necessarily_before(C, S, G).

%!  declobber_by(+Method, +Cond, +E, +S, +C, +Plan0, -Plan) is nondet.
%
%   Protect Cond, needed by S, from clobberer C by Method.

declobber_by(promotion, Cond, _, S, C, Plan0, Plan) :-
    post_prior_to(S, C, Plan0, Plan),
    note(Plan, "  ~q may clobber ~q: promotion prior_to(~q, ~q)~n",
         [C, Cond, S, C]).
declobber_by(separation, Cond, _, _, C, Plan0, Plan) :-
    plan_actions(Plan0, Actions),
    memberchk(action(C, _, _, _, dellist(Dels)), Actions),
    unifying(Dels, Cond, Unifying),
    Unifying \== [],
    plan_seps(Plan0, Seps0),
    separate(Unifying, Cond, Seps0, Seps),
    set_seps_of_plan(Seps, Plan0, Plan),
    note(Plan, "  ~q may clobber ~q: separation ~q~n", [C, Cond, Unifying]).
declobber_by(white_knight, Cond, _, S, C, Plan0, Plan) :-
    (   plan_adder(Cond, Plan0, W, Adds),
        W \== C, W \== S,
        member(Cond, Adds),
        post_prior_to(C, W, Plan0, Plan1),
        post_prior_to(W, S, Plan1, Plan)
    ;   new_action(Cond, W, [C-W, W-S], Plan0, Plan)
    ),
    note(Plan, "  ~q may clobber ~q: white knight ~q, prior_to(~q, ~q), \c
                prior_to(~q, ~q)~n", [C, Cond, W, C, W, W, S]).

%   unifying(+Dels, +Cond, -Ds): the elements of Dels that unify with Cond
%   (nothing is bound). No yall lambda here or in separate/4: a lambda
%   with free variables may be copied, and the dif/2 posted on the copy.

unifying([], _, []).
unifying([D|Ds], Cond, Us) :-
    (   \+ D \= Cond
    ->  Us = [D|Us1]
    ;   Us = Us1
    ),
    unifying(Ds, Cond, Us1).

%   separate(+Ds, +Cond, +Seps0, -Seps): post dif(D, Cond) for every D and
%   record sep(D, Cond). Fails if some D cannot be kept apart from Cond.

separate([], _, Seps, Seps).
separate([D|Ds], Cond, Seps0, Seps) :-
    dif(D, Cond),
    separate(Ds, Cond, [sep(D, Cond)|Seps0], Seps).
