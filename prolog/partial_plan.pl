/*  spar-py: the partial plan phase 1 returns (Sec. 2, Figs. 23-25) and the
    plan instances phase 2 takes from it (Sec. 3.3).

      Partial  = partial(Actions, Order, Net, Satisfied)   (spar.pl's header)
      Instance = instance(Steps, Bindings)

    Its readers, its plan instances, its dict for the JSON and its printed
    form. goals:plan_partial/2 builds it; spar.pl (the entry points),
    uncertainty.pl (phase 2) and spar_toplevel.pl (printing answers) read it
    here, so none of them needs another.
*/
:- module(partial_plan,
          [ partial_actions/2,       % +Partial, -Actions
            partial_ordering/2,      % +Partial, -PriorTos
            partial_network/2,       % +Partial, -Net
            partial_instances/2,     % +Partial, -Instance
            partial_instances/3,     % +Partial, +Nogoods, -Instance
            partial_dict/2,          % +Partial, -Dict
            print_partial/1          % +Partial
          ]).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(pairs)).
:- use_module(library(yall)).
:- use_module(cms, [cms_solution/3, cms_nodes/2, cms_pruned_nodes/2, cms_arcs/2]).
:- use_module(ordering, [ordering_arcs/2, linearisation/3, necessarily_before/3]).
:- use_module(goals, [print_action/1]).
:- use_module(foreign, [term_data/2]).
:- use_module(kb, []).

%!  partial_actions(+Partial, -Actions:list) is det.
%
%   The plan actions as action(Id, Term), newest first (Fig. 23).

partial_actions(partial(Actions, _, _, _), List) :-
    maplist([action(Id, T, _, _, _), action(Id, T)]>>true, Actions, List).

%!  partial_ordering(+Partial, -PriorTos:list) is det.
%
%   The ordering constraints as prior_to(A1, A2), in standard order.

partial_ordering(partial(_, Order, _, _), PriorTos) :-
    ordering_arcs(Order, PriorTos).

%!  partial_network(+Partial, -Net) is det.
%
%   The CMS network of the partial plan (see cms.pl).

partial_network(partial(_, _, Net, _), Net).

%!  partial_instances(+Partial, -Instance) is nondet.
%
%   A plan instance for phase 2 (Sec. 3.3): a solution of the network
%   combined with a linearisation of the ordering graph. Instance is
%   instance(Steps, Bindings): Steps the instantiated templates in
%   execution order with every network variable replaced by its label,
%   Bindings the Var = Label pairs in standard order of Var. Backtracking
%   enumerates solutions (outer) and linearisations (inner), lazily. A
%   solution that gives a separated pair sep(D, Cond) the same labels
%   (D would clobber Cond after all) is skipped.

partial_instances(Partial, Instance) :-
    partial_instances(Partial, nogoods([], 0), Instance).

%!  partial_instances(+Partial, +Nogoods, -Instance) is nondet.
%
%   As partial_instances/2, skipping every instance a nogood of Nogoods
%   rules out, without enumerating them: Nogoods is a term nogoods(List,
%   Checks) whose List phase 2 extends (nb_setarg/3) as instances fail,
%   read anew at each step of each linearisation and at each label of the
%   solution search (a nogood that holds in every linearisation rules the
%   label out there). Checks counts the steps checked: past 200000 the
%   rest is enumerated unpruned (every instance is tried, as by
%   partial_instances/2), so a search that prunes little costs little. A
%   nogood ng(Id, Action, GId,
%   GAction, Done, NotDone) (uncertainty.pl, from Python's
%   phase2.nogood) refuses action Id as the next one when, under the
%   solution at hand, Id's action is Action and GId's is GAction, every
%   id of Done is executed already and none of NotDone is: such an
%   instance fails at Id as the one the nogood came from did.

partial_instances(partial(Actions, Order, Net, Sat), Nogoods, instance(Steps, Bindings)) :-
    cms_solution(Net, label_allowed(Nogoods, Actions, Order), Assignment),
    forall(member(sep(D, Cond), Sat),
           ( substitute(Assignment, D, D1),
             substitute(Assignment, Cond, Cond1),
             D1 \= Cond1 )),
    linearisation(Order, not_ruled_out(Nogoods, Actions, Assignment), Ids),
    maplist(instance_step(Actions, Assignment), Ids, Steps),
    maplist([V-L, V=L]>>true, Assignment, Bindings).

not_ruled_out(Nogoods, Actions, Assignment, Done, V) :-
    Nogoods = nogoods(List, Checks0),
    Checks is Checks0 + 1,
    nb_setarg(2, Nogoods, Checks),
    (   Checks > 200000                  % the budget spent: no more pruning, every instance is tried
    ->  true
    ;   no_nogood(List, Actions, Assignment, Done, V)
    ).

no_nogood(List, Actions, Assignment, Done, V) :-
    \+ ( member(ng(V, A, GId, GA, InDone, OutDone), List),
          forall(member(I, InDone), memberchk(I, Done)),
          \+ ( member(O, OutDone), memberchk(O, Done) ),
          step_action(Actions, Assignment, V, A),
          step_action(Actions, Assignment, GId, GA)
        ).

%   label_allowed(+Nogoods, +Actions, +Order, +Var, +Label): no nogood rules
%   out Var = Label alone: one whose conditions hold in every
%   linearisation of Order (each of Done necessarily before its action,
%   each of NotDone necessarily after) and whose two actions are already
%   theirs with Var = Label and no other variable bound.

label_allowed(nogoods(List, _), Actions, Order, Var, Label) :-
    \+ ( member(ng(Id, A, GId, GA, Done, NotDone), List),
          step_action(Actions, [Var-Label], Id, A),
          step_action(Actions, [Var-Label], GId, GA),
          forall(member(I, Done), necessarily_before(I, Id, Order)),
          forall(member(O, NotDone), necessarily_before(Id, O, Order))
        ).

step_action(Actions, Assignment, Id, A) :-
    memberchk(action(Id, T, _, _, _), Actions),
    substitute(Assignment, T, A0),
    A0 == A.

instance_step(Actions, Assignment, Id, Step) :-
    memberchk(action(Id, T, Pre, Add, Del), Actions),
    substitute(Assignment, action(Id, T, Pre, Add, Del), Step).

substitute(Assignment, T0, T) :-
    (   atom(T0), memberchk(T0-L, Assignment)
    ->  T = L
    ;   compound(T0)
    ->  T0 =.. [F|As0],
        maplist(substitute(Assignment), As0, As),
        T =.. [F|As]
    ;   T = T0
    ).

%!  partial_dict(+Partial, -Dict) is det.
%
%   Partial as a dict for janus (the "partial" of the plan JSON, schema 2,
%   docs/json-schema.md):
%
%     _{actions: [_{id, term, name, args}],    newest first (Fig. 23)
%       ordering: [[Before, After]],           prior_to/2 (Fig. 24)
%       variables: _{Var: [Label]},             label sets after AC-3
%       raw_variables: _{Var: [Label]},         as posted (Fig. 25)
%       arcs: [_{vars: [V1, V2], pairs: [[L1, L2]]}],
%       separations: [_{deleted, condition, text}]}   dif(Deleted, Cond)
%                                                 posted by separation,
%                                                 oldest first
%
%   Arguments, deleted and condition are term data (foreign:term_data/2:
%   atoms as strings, compounds as _{functor, args}); term and text are
%   the same terms written with ~q, for display only. Ids, variables and
%   labels are atoms.

partial_dict(Partial, Dict) :-
    Partial = partial(Actions, _, Net, Sat),
    maplist(action_dict, Actions, ADicts),
    partial_ordering(Partial, PriorTos),
    maplist([prior_to(A, B), [A, B]]>>true, PriorTos, Ordering),
    cms_nodes(Net, Raw),
    (   cms_pruned_nodes(Net, Pruned) -> true ; Pruned = Raw ),
    dict_pairs(RawDict, _, Raw),
    dict_pairs(PrunedDict, _, Pruned),
    cms_arcs(Net, Arcs),
    maplist(arc_dict, Arcs, ArcDicts),
    findall(SD, ( member(sep(D, C), Sat), separation_dict(D, C, SD) ), Separations),
    Dict = _{actions: ADicts, ordering: Ordering, variables: PrunedDict,
             raw_variables: RawDict, arcs: ArcDicts,
             separations: Separations}.

separation_dict(D, C, _{deleted: DD, condition: CD, text: [DS, CS]}) :-
    term_data(D, DD),
    term_data(C, CD),
    format(string(DS), "~q", [D]),
    format(string(CS), "~q", [C]).

action_dict(action(Id, Term, _, _, _),
            _{id: Id, term: S, name: Name, args: ArgData}) :-
    format(string(S), "~q", [Term]),
    Term =.. [Name|Args],
    maplist(term_data, Args, ArgData).

arc_dict(arc(V1, V2, Pairs), _{vars: [V1, V2], pairs: Ps}) :-
    maplist([A/B, [A, B]]>>true, Pairs, Ps).

%!  print_partial(+Partial) is det.
%
%   Print Partial to current output: the plan actions as Fig. 23, the
%   ordering constraints, the network arcs and label sets as Fig. 25
%   (`grasp_1-pos_1: [p1G1/p2P1, ...]`), and the label sets after arc
%   consistency, and the separations posted (`sep(D, Cond)`: D, deleted
%   by a possible clobberer, is kept apart from Cond), if any.

print_partial(Partial) :-
    Partial = partial(Actions, _, Net, Sat),
    format("PLAN ACTIONS~n"),
    forall(member(A, Actions), print_action(A)),
    partial_ordering(Partial, PriorTos),
    format("ORDERING~n"),
    forall(member(P, PriorTos), print_prior_to(Actions, P)),
    print_mates(Actions, PriorTos),
    format("NETWORK ARCS~n"),
    cms_arcs(Net, Arcs),
    forall(member(arc(V1, V2, Pairs), Arcs),
           print_labelled(V1-V2, Pairs)),
    format("LABEL SETS~n"),
    cms_nodes(Net, Raw),
    forall(member(V-Ls, Raw), print_labels(V, Ls)),
    format("LABEL SETS AFTER ARC CONSISTENCY~n"),
    (   cms_pruned_nodes(Net, Pruned)
    ->  forall(member(V-Ls, Pruned), print_labels(V, Ls))
    ;   format("  (inconsistent)~n")
    ),
    (   memberchk(sep(_, _), Sat)
    ->  format("SEPARATIONS~n"),
        forall(member(sep(D, C), Sat),
               format("  dif(~W, ~W)~n",
                      [D, [quoted(true), spacing(next_argument)],
                       C, [quoted(true), spacing(next_argument)]]))
    ;   true
    ).

%   print_prior_to(+Actions, +PriorTo): one ordering constraint, and
%   where the product's geometry forces it (kb:precedence/3), why:
%   `prior_to(action_5, action_9): bracket before pin_a (...)`.

print_prior_to(Actions, prior_to(A, B)) :-
    format("  ~W", [prior_to(A, B), [quoted(true), spacing(next_argument)]]),
    (   memberchk(action(A, assemble(P, _, _, _, _), _, _, _), Actions),
        memberchk(action(B, assemble(Q, _, _, _, _), _, _, _), Actions),
        kb:precedence(P, Q, Reason)
    ->  format(": ~w before ~w (~w)~n", [P, Q, Reason])
    ;   nl
    ).

%   print_mates(+Actions, +PriorTos): for a product cell, the mates each assemble of
%   the partial plan makes, oldest action first: a mate is made by the
%   insertion that brings its two parts together, so an assemble makes
%   the mates (kb:mates/2) whose other part is never assembled (the base)
%   or is assembled necessarily before it; one whose other part's assemble
%   is unordered with it is made by whichever of the two a plan instance
%   takes later ("or by"). Nothing for a cell without a product.

print_mates(Actions, PriorTos) :-
    findall(Id-Made,
            ( member(action(Id, assemble(P, _, _, _, _), _, _, _), Actions),
              kb:mates(P, Pairs),
              mates_made(Pairs, Id, Actions, PriorTos, Made) ),
            Made0),
    (   Made0 == []
    ->  true
    ;   reverse(Made0, Made),
        format("MATES~n"),
        forall(member(Id-made(Sure, Either), Made), print_made(Id, Sure, Either))
    ).

%   mates_made(+Pairs, +Id, +Actions, +PriorTos, -made(Sure, Either)): of
%   the Name-Other pairs an assemble Id may make, the names it makes in
%   every linearisation of the ordering PriorTos (Sure) and those with
%   Other's assemble unordered with Id (Either, as Name-OtherAction).

mates_made(Pairs, Id, Actions, PriorTos, made(Sure, Either)) :-
    findall(Name,
            ( member(Name-Other, Pairs),
              (   other_assemble(Other, Actions, B)
              ->  path_before(B, Id, PriorTos)
              ;   true
              ) ),
            Sure),
    findall(Name-B,
            ( member(Name-Other, Pairs),
              other_assemble(Other, Actions, B),
              \+ path_before(B, Id, PriorTos),
              \+ path_before(Id, B, PriorTos) ),
            Either).

%   path_before(+A, +B, +PriorTos): a path A -> B of prior_to/2 arcs.

path_before(A, B, PriorTos) :-
    path_before(A, B, PriorTos, [A]).

path_before(A, B, PriorTos, Seen) :-
    member(prior_to(A, C), PriorTos),
    \+ memberchk(C, Seen),
    (   C == B -> true ; path_before(C, B, PriorTos, [C|Seen]) ),
    !.

other_assemble(Other, Actions, B) :-
    memberchk(action(B, assemble(Other, _, _, _, _), _, _, _), Actions).

print_made(Id, Sure, Either) :-
    atomic_list_concat(Sure, ', ', Text),
    format("  ~q makes ~w", [Id, Text]),
    forall(member(Name-B, Either),
           format("~w~w (or ~q, whichever comes later)", [", " , Name, B])),
    nl.

print_labels(V, Labels) :-
    map_list_to_pairs(natural_key, Labels, Keyed),
    keysort(Keyed, Sorted),
    pairs_values(Sorted, Natural),
    print_labelled(V, Natural).

%   print_labelled(+Head, +List): "  Head: [a,b,...]" wrapped at 76 columns.

print_labelled(Head, List) :-
    format(string(H), "  ~q: [", [Head]),
    string_length(H, Col0),
    format("~s", [H]),
    foldl(print_item(Col0), List, Col0-first, _),
    format("]~n").

print_item(Indent, X, Col0-State, Col-later) :-
    format(string(S), "~q", [X]),
    string_length(S, Len),
    (   State == first
    ->  Sep = "", Col1 = Col0
    ;   Col0 + Len + 1 > 76
    ->  format(",~n~*c", [Indent, 0'\s]), Sep = "", Col1 = Indent
    ;   Sep = ",", Col1 = Col0 + 1
    ),
    format("~s~s", [Sep, S]),
    Col is Col1 + Len.

%   natural_key(+Label, -Key): p1G11 sorts after p1G2.

natural_key(Label, Key) :-
    atom_codes(Label, Codes),
    phrase(chunks(Key), Codes).

chunks([C|Cs]) --> chunk(C), !, chunks(Cs).
chunks([]) --> [].

chunk(N) --> digit(D), digits(Ds), { number_codes(N, [D|Ds]) }.
chunk(A) --> nondigit(C), nondigits(Cs), { atom_codes(A, [C|Cs]) }.

digits([D|Ds]) --> digit(D), !, digits(Ds).
digits([]) --> [].
digit(D) --> [D], { code_type(D, digit) }.
nondigits([C|Cs]) --> nondigit(C), !, nondigits(Cs).
nondigits([]) --> [].
nondigit(C) --> [C], { \+ code_type(C, digit) }.
