/*  Tests of prolog/plan_state.pl (the phase-1 plan record, its accessors
    and the search recorder) and prolog/spar_defaults.pl (the defaults),
    and two checks on the layout they belong to: the planner's modules
    import one another without a circle, and every exported predicate of
    the phase-1 modules has a PlDoc comment directly above its clauses.

    swipl -g run_tests -t halt tests/prolog/plan_state.plt
*/
:- use_module('../../prolog/spar').
:- use_module('../../prolog/goals').
:- use_module('../../prolog/establish').
:- use_module('../../prolog/plan_state', except([plan_actions/2])).  % spar's toplevel has its own
:- use_module('../../prolog/spar_defaults').
:- use_module('../../prolog/ordering').
:- use_module(library(plunit)).
:- use_module(library(apply)).
:- use_module(library(lists)).
:- use_module(library(pairs)).
:- use_module(library(ugraphs)).
:- use_module(library(yall)).
:- use_module(library(pldoc)).
:- use_module(library(pldoc/doc_process)).

%   field(Name, Value, NewValue): one distinct value per field of the
%   record, in its order, and another for the writers.

field(actions,   [action(action_1, t, p, a, d)], []).
field(order,     [action_1-[]], [action_1-[], action_2-[]]).
field(net,       net_value, other_net).
field(ids,       [action-1], [action-2]).
field(ops,       [op(top_1, finish, g)], []).
field(geos,      [geo(goal_2, action_1, c, [])], []).
field(sat,       [sat(g, start)], []).
field(steps,     7, 8).
field(bound,     4, 5).
field(methods,   [promotion], [separation]).
field(trace,     true, false).
field(history,   [h(1, c, [])], []).
field(checked,   t(goal_2, true, <, t, t), t(goal_3, true, <, t, t)).
field(lookahead, false, true).
field(recorder,  recorder_value, other_recorder).
field(seps,      [sep(a, b)], []).
field(index,     index(t, t), index(t(k(f, 1), [], <, t, t), t)).
field(pending,   none, seen([], [])).

read_field(Plan, Name, Value) :-
    atom_concat(plan_, Name, Reader),
    call(plan_state:Reader, Plan, Value).

write_field(Name, Value, Plan0, Plan) :-
    atomic_list_concat([set_, Name, '_of_plan'], Writer),
    call(Writer, Value, Plan0, Plan).

settable(Name) :-
    atomic_list_concat([set_, Name, '_of_plan'], Writer),
    module_property(plan_state, exports(PIs)),
    memberchk(Writer/3, PIs).

full_plan(Plan) :-
    findall(F, ( field(Name, V, _), F =.. [Name, V] ), Fields),
    make_plan(Fields, Plan).

:- begin_tests(plan_state_record).

test(eighteen_fields, N == 18) :-
    make_plan([], P),
    functor(P, plan, N).

test(each_reader_its_field, Got == Want) :-
    full_plan(P),
    findall(Name-V, field(Name, V, _), Want),
    findall(Name-V, ( field(Name, _, _), read_field(P, Name, V) ), Got).

test(make_plan_order_free, true(P1 =@= P2)) :-
    make_plan([bound(3), steps(2)], P1),
    make_plan([steps(2), bound(3)], P2).

test(writer_sets_only_its_field, Bad == []) :-
    full_plan(P0),
    findall(Name-Other,
            ( field(Name, _, New),
              settable(Name),
              write_field(Name, New, P0, P),
              read_field(P, Name, New),
              field(Other, Old, _), Other \== Name,
              \+ read_field(P, Other, Old) ),
            Bad).

test(writers, Names == [actions, order, net, ids, ops, geos, sat, steps,
                        history, checked, recorder, seps, index, pending]) :-
    findall(Name, ( field(Name, _, _), settable(Name) ), Names).

test(push_history, [H-Same == [h(2, c2, []), h(1, c, [])]-true]) :-
    full_plan(P0),
    push_history_of_plan(h(2, c2, []), P0, P),
    plan_history(P, H),
    (   forall(( field(Name, _, _), Name \== history ),
               ( read_field(P0, Name, V0), read_field(P, Name, V), V0 == V ))
    ->  Same = true
    ;   Same = false
    ).

test(writer_type_list, [error(type_error(list, x))]) :-
    make_plan([], P),
    set_actions_of_plan(x, P, _).

test(writer_type_integer, [error(type_error(integer, many))]) :-
    make_plan([], P),
    set_steps_of_plan(many, P, _).

test(writer_partial_list, [error(instantiation_error)]) :-
    make_plan([], P),
    set_ops_of_plan([a|_], P, _).

test(writer_untyped_net, Net == anything) :-
    make_plan([], P0),
    set_net_of_plan(anything, P0, P),
    plan_net(P, Net).

test(reader_fails_on_non_plan, fail) :-
    plan_state:plan_actions(partial([], [], n, []), _).

test(defaults, [Bound, Methods, Trace, Lookahead, Lists, Order, Checked, Steps, Recorder] ==
               [12, [promotion, separation, white_knight], false, true,
                [[], [], [], [], [], [], []], Empty, t, 0,
                failures(none, none, false, 0-steps(0))]) :-
    make_plan([], P),
    empty_ordering(Empty),
    plan_bound(P, Bound), plan_methods(P, Methods),
    plan_trace(P, Trace), plan_lookahead(P, Lookahead),
    maplist(read_field(P), [actions, ids, ops, geos, sat, history, seps], Lists),
    plan_order(P, Order),
    plan_checked(P, Checked),
    plan_steps(P, Steps), plan_recorder(P, Recorder).

test(defaults_from_spar_defaults) :-
    make_plan([], P),
    plan_bound(P, B), default_option(max_actions_floor, B),
    plan_methods(P, Ms), default_option(declobber, Ms),
    plan_trace(P, T), default_option(trace, T),
    plan_lookahead(P, L), default_option(forward_check, L).

test(net_unbound_by_default, true(var(Net))) :-
    make_plan([], P),
    plan_net(P, Net).

test(make_plan_not_list, [error(type_error(list, bound(3)))]) :-
    make_plan(bound(3), _).

test(make_plan_unknown_field, [error(domain_error(plan_field, colour(red)))]) :-
    make_plan([colour(red)], _).

test(make_plan_not_a_field, [error(domain_error(plan_field, bound))]) :-
    make_plan([bound], _).

test(make_plan_type, [error(type_error(boolean, maybe))]) :-
    make_plan([trace(maybe)], _).

test(initial_plan_uses_defaults, Ms == Default) :-
    initial_plan(4, [oracle(no_oracle)], P),
    plan_methods(P, Ms),
    default_option(declobber, Default).

test(initial_plan_bound, [error(type_error(nonneg, -1))]) :-
    initial_plan(-1, [], _).

:- end_tests(plan_state_record).

:- begin_tests(plan_state_recorder).

recorded_plan(Budget, P) :-
    failure_recorder(Budget, R),
    make_plan([recorder(R)], P).

test(new_recorder, R == failures(none, none, false, 5-steps(0))) :-
    failure_recorder(5-steps(0), R).

test(bad_budget, [error(domain_error(step_budget, 5))]) :-
    failure_recorder(5, _).

test(deepest_kept_over_backtracking, [Op, Geo] == [3-op(g3, a, c), 2-geo(g2, a, k, [])]) :-
    recorded_plan(0-steps(0), P),
    (   member(K-G, [1-op(g1, a, c), 3-op(g3, a, c), 2-op(g2, a, c),
                     2-geo(g2, a, k, []), 1-geo(g1, a, k, [])]),
        record_failure(K, G, P),
        fail
    ;   true
    ),
    plan_recorder(P, R),
    recorder_deepest(R, Op, Geo).

test(nothing_failed, [Op, Geo] == [none, none]) :-
    recorded_plan(0-steps(0), P),
    plan_recorder(P, R),
    recorder_deepest(R, Op, Geo).

test(bound_hit_kept_over_backtracking) :-
    recorded_plan(0-steps(0), P),
    plan_recorder(P, R),
    \+ recorder_bound_hit(R),
    ( bound_hit(P), fail ; true ),
    recorder_bound_hit(R).

test(budget_spent, [throws(spar_step_budget)]) :-
    recorded_plan(2-steps(0), P),
    ( spend_step(P), spend_step(P), fail ; true ),
    spend_step(P).

test(budget_counts, N == 2) :-
    recorded_plan(2-steps(0), P),
    spend_step(P), spend_step(P),
    plan_recorder(P, failures(_, _, _, 2-steps(N))).

test(no_budget, N == 100) :-
    recorded_plan(0-steps(0), P),
    forall(between(1, 100, _), spend_step(P)),
    plan_recorder(P, failures(_, _, _, 0-steps(N))).

test(budget_shared_by_rounds, N == 3) :-
    Budget = 10-steps(0),
    recorded_plan(Budget, P1),
    recorded_plan(Budget, P2),
    spend_step(P1), spend_step(P2), spend_step(P2),
    Budget = _-steps(N).

test(note_silent, S == "") :-
    make_plan([trace(false)], P),
    with_output_to(string(S), note(P, "step ~d~n", [1])).

test(note_traces, S == "step 1\n") :-
    make_plan([trace(true)], P),
    with_output_to(string(S), note(P, "step ~d~n", [1])).

:- end_tests(plan_state_recorder).

:- begin_tests(spar_defaults).

test(max_actions, N == auto) :- default_option(max_actions, N).
test(max_actions_floor, N == 12) :- default_option(max_actions_floor, N).
test(derived_paper_cell, B == 12) :- derived_max_actions(4, B).
test(derived_fifty_pairs, B == 400) :- derived_max_actions(200, B).
test(derived_bad, [error(type_error(nonneg, -1))]) :- derived_max_actions(-1, _).
test(max_steps, N == auto) :- default_option(max_steps, N).
test(max_steps_floor, N == 10000) :- default_option(max_steps_floor, N).
test(derived_steps_small, S == 10000) :- derived_max_steps(4, S).
test(derived_steps_large, S == 40000) :- derived_max_steps(400, S).
test(max_instances, N == 50) :- default_option(max_instances, N).
test(declobber, Ms == [promotion, separation, white_knight]) :-
    default_option(declobber, Ms).
test(forward_check, B == true) :- default_option(forward_check, B).
test(trace, B == false) :- default_option(trace, B).

test(methods_known) :-
    default_option(declobber, Ms),
    forall(member(M, Ms), known_declobber_method(M)).

test(one_value_each, Dups == []) :-
    findall(N, default_option(N, _), Ns),
    msort(Ns, Sorted),
    findall(N, ( append(_, [N, N|_], Sorted) ), Dups).

test(dict_has_every_default, Keys == Names) :-
    default_options(D),
    dict_keys(D, Keys),
    findall(N, default_option(N, _), Ns),
    sort(Ns, Names).

test(dict_booleans_for_python, [FC, Tr] == [@(true), @(false)]) :-
    default_options(D),
    get_dict(forward_check, D, FC),
    get_dict(trace, D, Tr).

test(dict_values, [A, I, Ms] == [auto, 50, [promotion, separation, white_knight]]) :-
    default_options(D),
    get_dict(max_actions, D, A),
    get_dict(max_instances, D, I),
    get_dict(declobber, D, Ms).

dict_keys(D, Keys) :-
    dict_pairs(D, _, Pairs),
    pairs_keys(Pairs, Keys0),
    sort(Keys0, Keys).

:- end_tests(spar_defaults).

                 /*******************************
                 *            LAYOUT            *
                 *******************************/

%   module_file_(?Module, ?File): the planner's own modules.

module_file_(M, File) :-
    module_property(M, file(File)),
    sub_atom(File, _, _, _, '/prolog/'),
    \+ sub_atom(File, _, _, _, '/library/'),
    \+ sub_atom(File, _, _, _, '.plt').

%   imports(+File, -Files): the non-library files File loads with
%   use_module/1,2, read from its directives.

imports(File, Imported) :-
    file_directory_name(File, Dir),
    setup_call_cleanup(open(File, read, S), read_terms(S, Terms), close(S)),
    findall(Spec, ( member((:- use_module(Spec)), Terms)
                  ; member((:- use_module(Spec, _)), Terms) ),
            Specs),
    foldl(resolve(Dir), Specs, [], Imported0),
    sort(Imported0, Imported).

resolve(Dir, Spec, Fs, [F|Fs]) :-
    atom(Spec),
    !,
    absolute_file_name(Spec, F, [relative_to(Dir), file_type(prolog),
                                 access(read)]).
resolve(_, _, Fs, Fs).

read_terms(S, Terms) :-
    read_term(S, T, []),
    (   T == end_of_file
    ->  Terms = []
    ;   Terms = [T|Rest],
        read_terms(S, Rest)
    ).

import_graph(G) :-
    findall(F-Is, ( module_file_(_, F), imports(F, Is) ), Pairs),
    findall(I-[], ( member(_-Is, Pairs), member(I, Is) ), Leaves),
    append(Pairs, Leaves, All),
    keysort(All, Sorted),
    group_pairs_by_key(Sorted, Grouped),
    maplist([K-Lss, K-Ls]>>(append(Lss, Ls0), sort(Ls0, Ls)), Grouped, G0),
    vertices_edges_to_ugraph([], [], Empty),
    foldl([V-Ns, A0, A]>>( findall(V-N, member(N, Ns), Es),
                           add_edges(A0, Es, A1), add_vertices(A1, [V], A) ),
          G0, Empty, G).

%   documented(+File, -PI): File has a structured comment (%!) whose mode
%   lines name PI, and the term right after the comment is a clause of
%   one of the predicates it names.

structured_comments(File, Docs) :-
    setup_call_cleanup(open(File, read, S), comment_terms(S, Docs), close(S)).

comment_terms(S, Docs) :-
    read_term(S, T, [comments(Cs)]),
    (   T == end_of_file
    ->  Docs = []
    ;   findall(PIs-T, ( member(_-C, Cs),
                         is_structured_comment(C, _),
                         comment_modes(C, Modes),
                         maplist(mode_pi, Modes, PIs) ),
                Docs, Rest),
        comment_terms(S, Rest)
    ).

mode_pi(Mode, PI) :-
    (   Mode = (Head is _) -> true ; Head = Mode ),
    (   Head = //(H)
    ->  functor(H, N, A0), A is A0 + 2
    ;   functor(Head, N, A)
    ),
    PI = N/A.

clause_pi((H :- _), PI) :- !, clause_pi(H, PI).
clause_pi((H --> _), N/A) :- !, functor(H, N, A0), A is A0 + 2.
clause_pi(H, N/A) :- callable(H), H \= (:- _), functor(H, N, A).

documented_above(File, PI) :-
    structured_comments(File, Docs),
    member(PIs-T, Docs),
    memberchk(PI, PIs),
    clause_pi(T, TPI),
    memberchk(TPI, PIs).

:- begin_tests(layout).

test(import_graph_acyclic, Cycles == []) :-
    import_graph(G),
    findall(A-B, ( member(A-Ns, G), member(B, Ns),
                   reachable(B, G, Rs), memberchk(A, Rs) ),
            Cycles).

test(goals_establish_no_circle) :-
    once(module_file_(goals, G)),
    once(module_file_(establish, E)),
    once(module_file_(plan_state, P)),
    imports(E, EIs), \+ memberchk(G, EIs),
    imports(P, PIs), \+ memberchk(G, PIs), \+ memberchk(E, PIs).

test(pldoc_above_clauses, Undocumented == []) :-
    findall(M:PI,
            ( member(M, [plan_state, spar_defaults, goals, establish,
                         ordering, cms, csp]),
              module_file_(M, File),
              module_property(M, exports(PIs)),
              member(PI, PIs),
              \+ documented_above(File, PI) ),
            Undocumented).

:- end_tests(layout).
