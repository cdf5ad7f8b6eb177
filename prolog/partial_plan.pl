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
            path_before/3,           % +A, +B, +PriorTos
            partial_network/2,       % +Partial, -Net
            partial_instances/2,     % +Partial, -Instance
            instance_search/1,       % -Search
            next_instance/3,         % +Partial, +Search, -Instance
            search_examined/3,       % +Instance, +Search0, -Search
            search_nogood/3,         % +Nogood, +Search0, -Search
            instance_nogood/4,       % +Partial, +Instance, +Learnt, -Nogood
            partial_dict/2,          % +Partial, -Dict
            print_partial/1          % +Partial
          ]).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(pairs)).
:- use_module(library(yall)).
:- use_module(library(assoc)).
:- use_module(cms, [cms_solution/3, cms_solution/4, cms_nodes/2, cms_pruned_nodes/2, cms_arcs/2]).
:- use_module(ordering, [ordering_arcs/2, linearisation/2, linearisation/4, necessarily_before/3,
                        empty_ordering/1, ordering_add_action/3, prior_to/4]).
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

partial_instances(partial(Actions, Order, Net, Sat), Instance) :-
    cms_solution(Net, every_label, Assignment),
    separated(Sat, Assignment),
    linearisation(Order, Ids),
    instance_of(Actions, Assignment, Ids, Instance).

every_label(_, Labels, _, Labels).

%   separated(+Sat, +Assignment): no separated pair sep(D, Cond) gets the
%   same labels under Assignment.
separated(Sat, Assignment) :-
    forall(member(sep(D, Cond), Sat),
           ( substitute(Assignment, D, D1),
             substitute(Assignment, Cond, Cond1),
             D1 \= Cond1 )).

instance_of(Actions, Assignment, Ids, instance(Steps, Bindings)) :-
    maplist(instance_step(Actions, Assignment), Ids, Steps),
    maplist([V-L, V=L]>>true, Assignment, Bindings).

/*  Phase 2's instance search (uncertainty.pl): each next instance is
    searched anew, knowing every instance examined and every nogood learnt
    so far, so the instance after a failure changes a choice the failure
    depends on instead of the last choice made.

    A nogood is ng(Own, Labels, Prefix, Pairs), learnt from a run that
    stopped at a step it could not execute (instance_nogood/4): every
    instance whose bindings hold each Var-Label of Labels, whose order
    starts with the ids of Prefix and puts A before B for each A-B of
    Pairs cannot be executed (phase2.nogood in Python says why that is
    sure). Own are the failing step's own labels, each with a weight: its
    grasp 2, the rest (where it takes its part from or puts it) 1: what
    the next instance should change first, the grasp before the rest.

    The search (next_instance/3) is the enumeration of partial_instances/2
    with three changes: a label ruled out by a nogood that needs nothing
    of the order is never tried (the solution search refuses it as soon
    as the nogood's last variable gets its label); the variables of
    failing steps are searched first, the most failed first, and their
    labels that have failed least first (so the next instance changes the
    failing step's grasp, or where its part is when no other grasp fits
    there); and an order is cut at the first step
    that settles a nogood (the one that puts the last of its Prefix or
    Pairs in place). Instances examined already are skipped. A search
    that makes more than search_budget/1 checks gives up pruning and
    takes the first instance not examined yet, as partial_instances/2
    orders them: a nogood only saves the runs it would have skipped.
*/

%!  instance_search(-Search) is det.
%
%   The state of a new instance search: nothing examined, no nogood.

instance_search(search([], Examined)) :-
    empty_assoc(Examined).

%!  search_examined(+Instance, +Search0, -Search) is det.
%
%   Search0 with Instance examined: no later next_instance/3 gives it.

search_examined(instance(Steps, Bindings), search(Ngs, E0), search(Ngs, E)) :-
    maplist(arg(1), Steps, Ids),
    maplist([V=L, V-L]>>true, Bindings, Assignment),
    put_assoc(Ids-Assignment, E0, true, E).

%!  search_nogood(+Nogood, +Search0, -Search) is det.
%
%   Search0 with Nogood (ng/4, instance_nogood/4) learnt.

search_nogood(Ng, search(Ngs, E), search([Ng|Ngs], E)).

%!  instance_nogood(+Partial, +Instance, +Learnt, -Nogood) is semidet.
%
%   The nogood ng(Own, Labels, Prefix, Pairs) of a run of Instance that
%   stopped where Learnt says: Learnt is learnt(Step, LabelIds, Prefix,
%   Pairs0) with action ids (phase2.nogood): Labels the bindings of the
%   network variables of Step and of every action of LabelIds (in its
%   term and its operational preconditions: a grasp, where a part is
%   taken from or put), Own those of Step as Weight-(Var-Label), 2 for
%   its grasp (a pickup's, or the one its holding/2 precondition names)
%   and 1 for the others, Prefix as given and Pairs
%   the pairs of Pairs0 that some linearisation of Partial's ordering
%   breaks (the others hold in every instance). Fails if an id is not
%   one of Partial's actions or no linearisation keeps the pairs (then
%   there is no nogood: learning none is always sound).

instance_nogood(partial(Actions, Order, _, _), instance(_, Bindings),
                learnt(Step, Ids, Prefix, Pairs0), ng(Own, Labels, Prefix, Pairs)) :-
    findall(Id, ( member(Id, [Step|Ids]) ; member(Id, Prefix) ; member(A-B, Pairs0), member(Id, [A, B]) ), All),
    forall(member(Id, All), memberchk(action(Id, _, _, _, _), Actions)),
    action_grasp_labels(Actions, Bindings, Step, Grasp),
    action_labels(Actions, Bindings, Step, Mine),
    maplist(weighted(Grasp), Mine, Own),
    maplist(action_labels(Actions, Bindings), Ids, Lss),
    append([Mine|Lss], Labels0),
    sort(Labels0, Labels),
    ordering_closure(Order, G),
    \+ ( member(X-Y, Pairs0), necessarily_before(Y, X, G) ),
    exclude(kept_by(G), Pairs0, Pairs).

%   action_labels(+Actions, +Bindings, +Id, -Labels): the Var-Label pairs
%   of the network variables in action Id's term and operational
%   preconditions, in standard order.
action_labels(Actions, Bindings, Id, Labels) :-
    memberchk(action(Id, T, preconditions(Ops, _), _, _), Actions),
    findall(V-L, ( sub_term(V, T-Ops), atom(V), memberchk(V=L, Bindings) ), Labels0),
    sort(Labels0, Labels).

%   weighted(+Grasp, +VL, -W-VL): a failing step's label VL with its
%   weight: 2 for its grasp (a label of Grasp), 1 for the others.
weighted(Grasp, VL, W-VL) :-
    (   memberchk(VL, Grasp) -> W = 2 ; W = 1 ).

%   action_grasp_labels(+Actions, +Bindings, +Id, -Labels): the Var-Label
%   pairs of action Id's grasp variable: a pickup's own, else the one of
%   its holding/2 precondition.
action_grasp_labels(Actions, Bindings, Id, Labels) :-
    memberchk(action(Id, T, preconditions(Ops, _), _, _), Actions),
    findall(V-L, ( ( T = pickup(_, V) ; member(op(_, _, holding(_, V)), Ops) ),
                   atom(V), memberchk(V=L, Bindings) ),
            Labels0),
    sort(Labels0, Labels).

%!  search_budget(-Checks:integer) is det.
%
%   The checks (labels and order steps weighed against the nogoods) one
%   next_instance/3 makes before it gives up pruning.

search_budget(200000).

%!  next_instance(+Partial, +Search, -Instance) is semidet.
%
%   The next plan instance phase 2 examines (partial_instances/2's
%   Instance): one no nogood of Search rules out and not examined yet,
%   labels that have failed less often as a failing step's grasp tried
%   first (see above). Fails when there is none left.

next_instance(Partial, search(Ngs, Examined), Instance) :-
    search_budget(Limit),
    Budget = budget(0, Limit),
    catch(once(pruned_instance(Partial, Ngs, Examined, Budget, Instance)),
          phase2_search_budget,
          once(plain_instance(Partial, Examined, Instance))).

%   ordering_closure(+Order, -G): the ordering graph Order (a ugraph, as
%   the partial plan keeps it, or ordering.pl's graph) as ordering.pl's
%   graph, whose closure necessarily_before/3 reads.
ordering_closure(Order, G) :-
    (   Order = ord(_, _, _)
    ->  G = Order
    ;   empty_ordering(G0),
        foldl(add_node, Order, G0, G1),
        findall(A-B, ( member(A-Bs, Order), member(B, Bs) ), Arcs),
        foldl(add_arc, Arcs, G1, G)
    ).

add_node(V-_, G0, G) :-
    ordering_add_action(V, G0, G).

add_arc(A-B, G0, G) :-
    prior_to(A, B, G0, G).

%   kept_by(+G, +Pair): every linearisation of G puts A before B.
kept_by(G, A-B) :-
    necessarily_before(A, B, G).

pruned_instance(partial(Actions, Order, Net, Sat), Ngs, Examined, Budget, Instance) :-
    label_index(Ngs, Index),
    own_counts(Ngs, Counts, VarCounts),
    cms_solution(Net, failing_first(VarCounts), choose_labels(Index, Counts, Budget), Assignment),
    separated(Sat, Assignment),
    include(labels_hold(Assignment), Ngs, Held),
    maplist([ng(_, _, Prefix, Pairs), live(Prefix, Pairs)]>>true, Held, Live),
    empty_assoc(Placed),
    linearisation(Order, next_step(Budget), st(Placed, Live), Ids),
    \+ get_assoc(Ids-Assignment, Examined, _),
    instance_of(Actions, Assignment, Ids, Instance).

plain_instance(partial(Actions, Order, Net, Sat), Examined, Instance) :-
    cms_solution(Net, every_label, Assignment),
    separated(Sat, Assignment),
    linearisation(Order, Ids),
    \+ get_assoc(Ids-Assignment, Examined, _),
    instance_of(Actions, Assignment, Ids, Instance).

%   label_index(+Ngs, -Index): the assoc Var-Label -> [Labels] of the
%   nogoods that need nothing of the order, under each of their labels.
label_index(Ngs, Index) :-
    findall(VL-Labels, ( member(ng(_, Labels, [], []), Ngs), member(VL, Labels) ), KVs0),
    keysort(KVs0, KVs),
    group_pairs_by_key(KVs, Grouped),
    list_to_assoc(Grouped, Index).

%   own_counts(+Ngs, -Counts, -VarCounts): the assocs Var-Label -> and
%   Var -> the weights summed over the nogoods with them among their own
%   labels (how often, and how near the grasp, they failed).
own_counts(Ngs, Counts, VarCounts) :-
    findall(VL-W, ( member(ng(Own, _, _, _), Ngs), member(W-VL, Own) ), Ws),
    summed(Ws, Counts),
    findall(V-W, member(V-_-W, Ws), VWs),
    summed(VWs, VarCounts).

summed(KWs0, Assoc) :-
    keysort(KWs0, KWs),
    group_pairs_by_key(KWs, Grouped),
    maplist(sum_of, Grouped, Sums),
    list_to_assoc(Sums, Assoc).

sum_of(K-Ws, K-N) :-
    sum_list(Ws, N).

%   failing_first(+VarCounts, +Vars0, -Vars): csp:solution/4's order: the
%   variables of Vars0 most failed first, the rest in Vars0's order.
failing_first(VarCounts, Vars0, Vars) :-
    map_list_to_pairs(most_failed_key(VarCounts), Vars0, Keyed),
    keysort(Keyed, Sorted),
    pairs_values(Sorted, Vars).

most_failed_key(VarCounts, V, K) :-
    (   get_assoc(V, VarCounts, N) -> K is -N ; K = 0 ).

%   choose_labels(+Index, +Counts, +Budget, +Var, +LabelSet, +Assigned,
%   -Labels): csp:solution/3's hook: the labels of Var no nogood of Index
%   rules out with the variables Assigned, fewest failures first (ties in
%   label-set order).
choose_labels(Index, Counts, Budget, V, LabelSet, Assigned, Labels) :-
    tick(Budget),
    exclude(ruled_out(Index, V, Assigned), LabelSet, Allowed),
    map_list_to_pairs(failures(Counts, V), Allowed, Keyed),
    keysort(Keyed, Sorted),
    pairs_values(Sorted, Labels).

ruled_out(Index, V, Assigned, L) :-
    get_assoc(V-L, Index, LabelSets),
    member(Labels, LabelSets),
    forall(member(W-M, Labels), ( W == V -> M == L ; get_assoc(W, Assigned, M) )),
    !.

failures(Counts, V, L, N) :-
    (   get_assoc(V-L, Counts, N) -> true ; N = 0 ).

labels_hold(Assignment, ng(_, Labels, _, _)) :-
    forall(member(V-L, Labels), memberchk(V-L, Assignment)).

%   next_step(+Budget, +V, +St0, -St): ordering:linearisation/4's hook.
%   St is st(Placed, Live): the ids placed so far (an assoc) and, for each
%   nogood whose labels the instance has, live(Prefix, Pairs) with what
%   is still open of its order. V goes next unless it settles a nogood;
%   a nogood V contradicts is dropped.
next_step(Budget, V, st(Placed0, Live0), st(Placed, Live)) :-
    tick(Budget),
    foldl(advance(V, Placed0), Live0, Live, []),
    put_assoc(V, Placed0, true, Placed).

%   advance(+V, +Placed, +Live0, -Live, ?Tail): Live0 after V is placed,
%   kept in Live if still open, dropped if contradicted; fails if settled.
advance(V, Placed, live(Prefix0, Pairs0), Live, Tail) :-
    (   prefix_after(Prefix0, V, Prefix),
        pairs_after(Pairs0, V, Placed, Pairs)
    ->  ( Prefix == [], Pairs == [] -> fail ; Live = [live(Prefix, Pairs)|Tail] )
    ;   Live = Tail
    ).

prefix_after([], _, []).
prefix_after([P|Ps], V, Ps) :-
    P == V.

%   pairs_after(+Pairs0, +V, +Placed, -Pairs): the pairs A-B still open
%   once V goes after the ids Placed; fails if V is a B whose A is not
%   placed.
pairs_after([], _, _, []).
pairs_after([A-B|Ps0], V, Placed, Ps) :-
    (   A == V
    ->  Ps = Ps1
    ;   B == V
    ->  get_assoc(A, Placed, _),
        Ps = Ps1
    ;   Ps = [A-B|Ps1]
    ),
    pairs_after(Ps0, V, Placed, Ps1).

tick(Budget) :-
    arg(1, Budget, N0),
    N is N0 + 1,
    nb_setarg(1, Budget, N),
    (   arg(2, Budget, Limit), N > Limit
    ->  throw(phase2_search_budget)
    ;   true
    ).

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

%!  path_before(+A, +B, +PriorTos:list) is semidet.
%
%   A path A -> B of prior_to/2 arcs in PriorTos (partial_ordering/2's
%   list): A precedes B in every linearisation.

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
