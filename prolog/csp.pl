/*  spar-py: consistency of the geometric binary constraint network
    (Sec. 5.2.1, Figs. 15-17).

    A network here is net(Nodes, Arcs):

      Nodes  an assoc Var -> ordset of labels (the label sets)
      Arcs   an assoc V1-V2 -> ordset of L1/L2 pairs (the allowed pairs of
             the undirected arc between V1 and V2; stored once, under the
             orientation it was created with)

    csp/3 is the paper's Fig. 17 depth-first search with backtracking; it
    decides consistency (consistent/1) and, on backtracking, enumerates
    every solution (solution/2: plan instances for phase 2). It checks a
    label only against the assigned variables that share an arc with it;
    choose_one/4 and all_consistent/3 are the figure's own predicates, which
    check every previous assignment: csp/3 does not call them, and
    tests/prolog/csp_search.plt checks that both give the same solutions in
    the same order. ac3/2 is arc consistency (AC-3), used to show users
    label sets pruned of labels that no solution can use; the planner's
    consistency test is the search of Fig. 17.
*/
:- module(csp,
          [ csp/3,                  % +VarSet, +Net, -Result
            choose_one/4,           % +Var, +Net, +PrevAssns, -Label
            all_consistent/3,       % +Var/Label, +PrevAssns, +Net
            consistent/1,           % +Net
            solution/2,             % +Net, -Assignment
            solution/3,             % +Net, :Choose, -Assignment
            solution/4,             % +Net, :Order, :Choose, -Assignment
            ac3/2,                  % +Net, -PrunedNodes
            get_label_set/3,        % +Var, -LabelSet, +Net
            get_constraint_pairs/4  % +Var, +V1, -Pairs, +Net
          ]).
:- use_module(library(assoc)).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(ordsets)).
:- use_module(library(pairs)).
:- use_module(library(yall)).

%!  csp(+VarSet:list, +Net, -Result:list) is nondet.
%
%   Result is a consistent assignment [V/Label, ...] of every variable of
%   VarSet (Fig. 17): labels come from the label sets of Net and every pair
%   of assigned variables joined by an arc takes an allowed pair. The most
%   recently assigned variable comes first in Result. Backtracking gives the
%   next assignment.
%
%   The search is the one of Fig. 17 (variables in VarSet's order, labels in
%   label-set order, the same answers in the same order); a label is checked
%   only against the assigned variables joined to Var by an arc, found
%   through a table built once per search (arcs_by_var/2), not by looking up
%   an arc between Var and every previous assignment as all_consistent/3
%   does.

csp(VarSet, Constraints, Result) :-
    csp(VarSet, Constraints, all_labels, Result).

%   all_labels(+Var, +LabelSet, +Assigned, -Labels): every label, in
%   label-set order (csp/3, solution/2).
all_labels(_, Labels, _, Labels).

csp(VarSet, Constraints, Choose, Result) :-
    arcs_by_var(Constraints, ByVar),
    empty_assoc(Assigned),
    csp(VarSet, Constraints, ByVar, Choose, Assigned, [], Result).

csp([], _, _, _, _, R, R).
csp([V|Rest], Constraints, ByVar, Choose, Assigned, Asns, R) :-
    get_label_set(V, LabelSet, Constraints),
    (   get_assoc(V, ByVar, Arcs)
    ->  true
    ;   Arcs = []
    ),
    call(Choose, V, LabelSet, Assigned, Labels),
    member(Label, Labels),
    agrees(Arcs, Label, Assigned),
    put_assoc(V, Assigned, Label, Assigned1),
    csp(Rest, Constraints, ByVar, Choose, Assigned1, [V/Label|Asns], R).

%   agrees(+Arcs, +Label, +Assigned): Label of a variable V agrees with every
%   assigned variable V1 of its arcs V1-fwd(Pairs) (Pairs are V-label/V1-label)
%   and V1-rev(Pairs) (Pairs are V1-label/V-label).

agrees([], _, _).
agrees([V1-Dir|Arcs], Label, Assigned) :-
    (   get_assoc(V1, Assigned, L1)
    ->  allowed(Dir, Label, L1)
    ;   true
    ),
    agrees(Arcs, Label, Assigned).

allowed(fwd(Pairs), Label, L1) :-
    ord_memberchk(Label/L1, Pairs).
allowed(rev(Pairs), Label, L1) :-
    ord_memberchk(L1/Label, Pairs).

%   arcs_by_var(+Net, -ByVar): the assoc Var -> [V1-fwd(Pairs)|V1-rev(Pairs)]
%   of the arcs at each variable, in the orientation get_constraint_pairs/4
%   uses (an arc stored as Var-V1 wins over one stored as V1-Var).

arcs_by_var(net(_, Arcs), ByVar) :-
    assoc_to_list(Arcs, KPs),
    foldl(arc_ends(Arcs), KPs, Ends, []),
    keysort(Ends, Sorted),
    group_pairs_by_key(Sorted, Grouped),
    list_to_assoc(Grouped, ByVar).

arc_ends(Arcs, (V1-V2)-Pairs, [V1-(V2-fwd(Pairs))|Ends0], Ends) :-
    (   get_assoc(V2-V1, Arcs, _)
    ->  Ends0 = Ends
    ;   Ends0 = [V2-(V1-rev(Pairs))|Ends]
    ).

%!  choose_one(+Var, +Net, +PrevAssns, -Label) is nondet.
%
%   Label is a label of Var consistent with the previous assignments.

choose_one(Var, Constraints, PrevAssns, Label) :-
    get_label_set(Var, LabelSet, Constraints),
    member(Label, LabelSet),
    all_consistent(Var/Label, PrevAssns, Constraints).

%!  all_consistent(+VarLabel, +PrevAssns, +Net) is semidet.
%
%   Var/Label agrees with every previous assignment V1/L1 whose variable is
%   joined to Var by an arc.

all_consistent(_, [], _).
all_consistent(Var/Label, [V1/L1|Rest], Constraints) :-
    get_constraint_pairs(Var, V1, Pairs, Constraints),
    !,
    ord_memberchk(Label/L1, Pairs),
    all_consistent(Var/Label, Rest, Constraints).
all_consistent(Var/Label, [_|Rest], Constraints) :-
    all_consistent(Var/Label, Rest, Constraints).

%!  get_label_set(+Var, -LabelSet, +Net) is semidet.
%
%   The label set of Var's node; fails if Var has no node.

get_label_set(Var, LabelSet, net(Nodes, _)) :-
    get_assoc(Var, Nodes, LabelSet).

%!  get_constraint_pairs(+Var, +V1, -Pairs, +Net) is semidet.
%
%   Pairs are the allowed pairs Label/L1 of the arc between Var and V1,
%   oriented Var first (an ordset); fails if there is no such arc.

get_constraint_pairs(Var, V1, Pairs, net(_, Arcs)) :-
    (   get_assoc(Var-V1, Arcs, Pairs)
    ->  true
    ;   get_assoc(V1-Var, Arcs, Pairs0)
    ->  maplist(flip, Pairs0, Pairs1),
        sort(Pairs1, Pairs)
    ).

flip(A/B, B/A).

%!  consistent(+Net) is semidet.
%
%   Net has at least one solution (Sec. 5.2.1).

consistent(Net) :-
    net_vars(Net, Vars),
    once(csp(Vars, Net, _)).

%!  solution(+Net, -Assignment:list) is nondet.
%
%   Assignment is a solution of Net as Var-Label pairs ordered by Var;
%   backtracking enumerates all solutions, lazily.
%
%   ==
%   ?- fig15(Net), findall(S, solution(Net, S), Ss).   % tests/prolog/csp.plt
%   Ss = [[v1-1,v2-2,v3-4], [v1-2,v2-2,v3-4]].
%   ==

solution(Net, Assignment) :-
    solution(Net, all_labels, Assignment).

:- meta_predicate solution(+, 4, -).

%!  solution(+Net, :Choose, -Assignment:list) is nondet.
%
%   As solution/2, the labels of each variable V tried in the order of
%   call(Choose, V, LabelSet, Assigned, Labels) when V is chosen: Labels
%   is a sublist of LabelSet in the order to try, Assigned the assoc of
%   the variables assigned before V to their labels (phase 2 leaves out
%   the labels it has ruled out and tries first those that have failed
%   least, partial_plan.pl).
%
%   ==
%   ?- fig15(Net), findall(S, solution(Net, [_, Ls, _, Rs]>>reverse(Ls, Rs), S), Ss).
%   Ss = [[v1-2,v2-2,v3-4], [v1-1,v2-2,v3-4]].
%   ==

solution(Net, Choose, Assignment) :-
    solution(Net, same_order, Choose, Assignment).

same_order(Vars, Vars).

:- meta_predicate solution(+, 2, 4, -).

%!  solution(+Net, :Order, :Choose, -Assignment:list) is nondet.
%
%   As solution/3, the variables searched in the order call(Order, Vars0,
%   Vars) makes of the first-fail order Vars0 (a permutation: phase 2
%   searches the variables of failing steps first).

solution(Net, Order, Choose, Assignment) :-
    net_vars(Net, Vars0),
    call(Order, Vars0, Vars),
    csp(Vars, Net, Choose, Result),
    maplist([V/L, V-L]>>true, Result, Pairs),
    keysort(Pairs, Assignment).

%   Variables are searched in order of increasing label-set size (ties in
%   standard order), the usual first-fail choice of the "head of Nodes".

net_vars(net(Nodes, _), Vars) :-
    assoc_to_list(Nodes, VLs),
    map_list_to_pairs([_-Ls, N]>>length(Ls, N), VLs, Sized),
    keysort(Sized, Sorted),
    pairs_values(Sorted, SortedVLs),
    pairs_keys(SortedVLs, Vars).

%!  ac3(+Net, -Nodes) is semidet.
%
%   Nodes is the assoc of label sets of Net made arc consistent (AC-3):
%   a label stays only if every arc at its node has a pair supporting it
%   with a label still in the other node. Fails if a label set becomes
%   empty. AC-3 removes no label of any solution.

ac3(net(Nodes0, Arcs), Nodes) :-
    assoc_to_keys(Arcs, Keys),
    foldl([V1-V2, Q0, Q]>>append(Q0, [V1-V2, V2-V1], Q), Keys, [], Queue),
    ac3_loop(Queue, Keys, Arcs, Nodes0, Nodes).

ac3_loop([], _, _, Nodes, Nodes).
ac3_loop([X-Y|Queue], Keys, Arcs, Nodes0, Nodes) :-
    revise(X, Y, net(Nodes0, Arcs), Nodes0, Nodes1, Changed),
    (   Changed == true
    ->  get_assoc(X, Nodes1, LX),
        LX \== [],
        findall(Z-X, ( neighbour(X, Keys, Z), Z \== Y ), New),
        append(Queue, New, Queue1)
    ;   Queue1 = Queue
    ),
    ac3_loop(Queue1, Keys, Arcs, Nodes1, Nodes).

neighbour(X, Keys, Z) :-
    (   member(X-Z, Keys) ; member(Z-X, Keys) ).

revise(X, Y, Net, Nodes0, Nodes, Changed) :-
    get_assoc(X, Nodes0, LX),
    get_assoc(Y, Nodes0, LY),
    get_constraint_pairs(X, Y, Pairs, Net),
    include(supported(Pairs, LY), LX, LX1),
    (   LX1 == LX
    ->  Nodes = Nodes0, Changed = false
    ;   put_assoc(X, Nodes0, LX1, Nodes), Changed = true
    ).

supported(Pairs, LY, Lx) :-
    member(Lx/Ly, Pairs),
    ord_memberchk(Ly, LY),
    !.
