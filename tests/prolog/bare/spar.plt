/*  Tests of the planner loaded by a bare swipl: prolog/spar.pl alone, as
    `swipl prolog/spar.pl` loads it, with Python reached through janus
    (PYTHONPATH names src/, VIRTUAL_ENV the venv). Nothing is consulted
    into user but spar's exports, so a call that resolves only through
    user (a qualified call to a module that does not exist, a predicate
    used without its import) is an error here, where the embedded engine
    of spar_py.planning.engine would hide it.

    tests/test_prolog_bare.py runs this file; by hand:

    PYTHONPATH=src VIRTUAL_ENV=.venv swipl -g run_tests -t halt tests/prolog/bare/spar.plt

    It is not in tests/prolog itself: spar_py.app.plunit runs the .plt
    files there in the embedded engine, where these tests would prove
    nothing.
*/
:- use_module('../../../prolog/spar').
:- use_module(library(plunit)).
:- use_module(library(prolog_codewalk)).
:- use_module(library(lists)).
:- use_module(library(apply)).

:- prolog_load_context(directory, Dir),
   asserta(bare_test_dir(Dir)).

%   problem_file(+Name, -File): kb/problems/Name.yaml of this checkout.
problem_file(Name, File) :-
    bare_test_dir(Dir),
    atomic_list_concat([Dir, '/../../../kb/problems/', Name, '.yaml'], File0),
    absolute_file_name(File0, File, [access(read)]).

%   planner_module(?M): a module loaded from prolog/ or kb/templates/.
planner_module(M) :-
    bare_test_dir(Dir),
    atomic_list_concat([Dir, '/../../..'], Root0),
    absolute_file_name(Root0, Root, [file_type(directory)]),
    atomic_list_concat([Root, '/prolog/'], P),
    atomic_list_concat([Root, '/kb/templates/'], T),
    current_module(M),
    module_property(M, file(F)),
    (   sub_atom(F, 0, _, _, P) ; sub_atom(F, 0, _, _, T) ).

:- dynamic undefined_call/2.

%   Called by prolog_walk_code/1 for a call to an undefined predicate.
note_undefined(Callee, Caller, _Location) :-
    assertz(undefined_call(Callee, Caller)).

%   undefined_planner_calls(-Calls): Callee-Caller (each M:Name/Arity) for
%   every call a planner module makes to an undefined predicate, sorted.
undefined_planner_calls(Calls) :-
    retractall(undefined_call(_, _)),
    prolog_walk_code([ module_class([user, library]),
                       undefined(trace),
                       on_trace(note_undefined)
                     ]),
    findall(CalleePI-CallerPI,
            ( undefined_call(Callee, Caller),
              strip_module(Caller, M, _),
              planner_module(M),
              goal_pi(Callee, CalleePI),
              goal_pi(Caller, CallerPI) ),
            Calls0),
    sort(Calls0, Calls).

goal_pi(M:G, M:Name/Arity) :-
    functor(G, Name, Arity).

:- begin_tests(bare_spar).

%   Every call in the planner's clauses reaches a defined predicate (what
%   list_undefined/0 reports), meta-calls of known meta-predicates
%   included.
test(no_undefined_calls, Undefined == []) :-
    undefined_planner_calls(Undefined).

%   The paper's cell (Sec. 6), both phases with the default options
%   (spar_defaults.pl): the four actions of Fig. 23 and an instance with
%   no error.
test(paper_cell, [ Actions == [ action(action_4, pickup(block, grasp_2)),
                                action(action_3, putdown(block, pos_1)),
                                action(action_2, pickup(peg, grasp_1)),
                                action(action_1, assemble(peg, block,
                                                          [[peg_face], [block_face]],
                                                          trans_1, vec_1)) ],
                   Errors == 0 ]) :-
    problem_file(peg_in_block, File),
    load_problem(File, Problem),
    assertion(Problem == peg_in_block),
    plan(Problem, plan(Partial, Result)),
    partial_actions(Partial, Actions),
    Result = ur(Best, _, _, _),
    arg(2, Best, Errors),
    with_output_to(string(S), print_plan(plan(Partial, Result))),
    assertion(sub_string(S, _, _, _, "PLAN INSTANCE")),
    unload_problem(Problem).

%   A hole that starts on its side: phase 1's lower bound asks the
%   templates which grasps of the peg mate with it there
%   (goals:no_mate_at/6), and the plan is the pickup and the assemble.
test(sideways_hole, Terms == [ pickup(tab_peg, grasp_1),
                               assemble(tab_peg, socket_block, [[shaft], [socket]],
                                        trans_1_t5, vec_1) ]) :-
    problem_file(tab_peg_sideways, File),
    load_problem(File, Problem),
    phase1(Problem, [], plan(Partial)),
    partial_actions(Partial, Actions),
    findall(T, member(action(_, T), Actions), Terms),
    unload_problem(Problem).

:- end_tests(bare_spar).
