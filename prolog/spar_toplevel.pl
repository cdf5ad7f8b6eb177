/*  spar-py: the Prolog toplevel of `spar repl` (load problems, print plans,
    scripted sessions).

    What a user at the toplevel needs beyond spar.pl's entry points:

      - load_problem/1,2 reads a problem file through the Python loader
        (every KB check applies) and keeps it loaded beside the others;
        loaded_problems/1 lists them, unload_problem/1 forgets one;
      - print_plan/1 prints a plan/2 answer, both phases; an answer shows
        a plan, a partial plan or a plan step as a one-line summary (a
        portray/1 hook: `<plan peg_in_block: 4 actions, 4 steps, 0
        expected failures>`), so print_plan/1 is the one full printing;
      - plan_actions/2, plan_outcome/2, plan_step/3, step_action/2,
        step_id/2, step_joints/2 and step_verdicts/2 read a plan without
        printing it (a step's geometry stays in Python: step_joints/2
        asks for it by the run's token);
      - batch_toplevel/0 runs a script read from standard input one query
        at a time (each answered once, bindings printed), for a piped
        `spar repl` where the interactive toplevel would read the next
        query as its answer to "more solutions?";
      - help/1 shows the PlDoc of the planner's predicates (help(plan/2))
        once collect_docs/0 has reloaded the planner with PlDoc on (the
        SWI-Prolog spar-py builds has no manual, so library(help) is
        absent; where it is present, help/1 falls back to it).
*/
:- module(spar_toplevel,
          [ load_problem/1,          % +File
            load_problem/2,          % +File, -Problem
            loaded_problems/1,       % -Problems
            unload_problem/1,        % +Problem
            print_plan/1,            % +Plan
            plan_actions/2,          % +Plan, -Actions
            plan_outcome/2,          % +Plan, -Outcome
            plan_step/3,             % +Plan, ?N, -Step
            step_id/2,               % +Step, -Id
            step_action/2,           % +Step, -Action
            step_joints/2,           % +Step, -JointsDeg
            step_verdicts/2,         % +Step, -Verdicts
            batch_toplevel/0,
            collect_docs/0,
            spar_help/1              % +Spec
          ]).
:- use_module(library(error)).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(yall)).
:- use_module(kb, [loaded_problem/1]).
:- use_module(foreign, [load_problem_file/2, unload_problem_cell/1]).
:- use_module(partial_plan, [print_partial/1, partial_actions/2, partial_ordering/2]).
:- use_module(uncertainty, [print_ur/1, step_id_text/2]).
:- use_module(foreign, [py_bridge/2]).
:- use_module(spar_paths, []).    % the file search path spar
:- autoload(library(pldoc/doc_process), [doc_comment/4]).  % loaded by spar_help/1

%!  load_problem(+File) is det.
%!  load_problem(+File, -Problem) is det.
%
%   Load the problem file File (a YAML problem, checked by the Python
%   loader) and keep it loaded under its name Problem; a problem of that
%   name loaded before is replaced, others stay loaded.
%
%   ==
%   ?- load_problem('kb/problems/two_pegs.yaml', P), plan(P, Plan).
%   ==
%
%   @error spar_error(Message) if the file is not a valid problem.

load_problem(File) :-
    load_problem(File, _).

load_problem(File, Problem) :-
    must_be(atomic, File),
    load_problem_file(File, Problem).

%!  loaded_problems(-Problems:list(atom)) is det.
%
%   The names of the loaded problems, in load order.

loaded_problems(Problems) :-
    findall(P, loaded_problem(P), Problems).

%!  unload_problem(+Problem) is det.
%
%   Forget the loaded problem Problem (nothing if it is not loaded).

unload_problem(Problem) :-
    must_be(atom, Problem),
    unload_problem_cell(Problem).

		 /*******************************
		 *        PRINTING PLANS        *
		 *******************************/

%!  print_plan(+Plan) is det.
%
%   Print a plan/3 result: the partial plan (Figs. 23-25) and the chosen
%   plan instance with its sensing, verdicts, verifications and recoveries.

print_plan(Plan) :-
    plan_parts(Plan, Partial, Result),
    print_partial(Partial),
    print_ur(Result).

		 /*******************************
		 *        READING PLANS         *
		 *******************************/

%   A plan is plan(Partial, Result) (plan/2); Result is phase 2's
%   ur(aug(Steps, Errors, Verifications, Recoveries, Verdicts, geo(Problem,
%   Token), Bindings), Examined, Cap, Complete) or no_instance(Examined,
%   Cap, Complete). A step read from it is
%   plan_step(N, Id, Action, Verdicts, Geo): opaque, read it with the
%   step_*/2 predicates below.

%!  plan_actions(+Plan, -Actions:list) is det.
%
%   The phase-1 actions of Plan as action(Id, Term), newest first (Fig.
%   23). Their terms hold the plan variables (grasp_1, pos_1); the bound
%   labels are in the steps (plan_step/3, step_action/2).
%
%   ==
%   ?- plan(peg_in_block, P), plan_actions(P, As).
%   ==

plan_actions(Plan, Actions) :-
    plan_parts(Plan, Partial, _),
    partial_actions(Partial, Actions).

%!  plan_outcome(+Plan, -Outcome) is det.
%
%   What phase 2 made of Plan: certain (every uncertainty-reduction
%   precondition holds), expected_failures(N) (N > 0 actions are expected
%   to fail: each has a verification and a recovery), or no_instance (no
%   plan instance could be executed).

plan_outcome(Plan, Outcome) :-
    plan_parts(Plan, _, Result),
    (   Result = ur(Aug, _, _, _)
    ->  arg(2, Aug, E),
        (   E =:= 0 -> Outcome = certain ; Outcome = expected_failures(E) )
    ;   Outcome = no_instance
    ).

%!  plan_step(+Plan, ?N:positive_integer, -Step) is nondet.
%
%   Step is the N-th step (1-based, execution order) of Plan's chosen
%   instance, inserted sensing and squeezes included. With N unbound,
%   enumerates the steps in order; fails if there is no such step (or no
%   instance). Read Step with step_id/2, step_action/2, step_joints/2 and
%   step_verdicts/2; the toplevel shows it as `<step N Id: Action>`.
%
%   ==
%   ?- plan(peg_in_block, P), plan_step(P, 3, S), step_joints(S, Q).
%   ==

plan_step(Plan, N, plan_step(N, Id, Action, Vs, Geo)) :-
    plan_parts(Plan, _, Result),
    (   var(N) -> true ; must_be(positive_integer, N) ),
    Result = ur(aug(Steps, _, _, _, Verdicts, Geo, _), _, _, _),
    nth1(N, Steps, step(Id, Action)),
    (   memberchk(verdict(Id, _, Vs0), Verdicts) -> Vs = Vs0 ; Vs = [] ).

%!  step_id(+Step, -Id) is det.
%
%   The id of a plan step: the action's id (action_2), or the inserted
%   step's sense(Action, K) or squeeze(Action).

step_id(Step, Id) :-
    must_be_step(Step),
    arg(2, Step, Id).

%!  step_action(+Step, -Action) is det.
%
%   The action term of a plan step, its plan variables bound to the
%   labels of the chosen instance (pickup(peg, p1G10)).

step_action(Step, Action) :-
    must_be_step(Step),
    arg(3, Step, Action).

%!  step_verdicts(+Step, -Verdicts:list(dict)) is det.
%
%   The verdicts of the preconditions checked at a plan step, one dict
%   each (constraint, kind = uncertainty | geometric, bound, sense,
%   threshold, satisfied = @true | @false, description); [] if none.

step_verdicts(Step, Verdicts) :-
    must_be_step(Step),
    arg(4, Step, Verdicts).

%!  step_joints(+Step, -JointsDeg:list(float)) is semidet.
%
%   The arm's joint angles (degrees, q1..q6) at the end of a plan step,
%   asked of the planning run that keeps the step's geometry; fails for
%   a step without joints (sensing).
%
%   @error the run's message if it no longer keeps the geometry (its
%   problem was unloaded or reloaded since).

step_joints(Step, Joints) :-
    must_be_step(Step),
    Step = plan_step(_, Id, _, _, geo(Problem, Token)),
    step_id_text(Id, T),
    py_bridge(step_geometry(Problem, Token, T), G),
    get_dict(joints_deg, G, Joints),
    is_list(Joints).

plan_parts(Plan, Partial, Result) :-
    must_be(nonvar, Plan),
    (   Plan = plan(Partial, Result), is_partial(Partial)
    ->  true
    ;   type_error(plan, Plan)
    ).

must_be_step(Step) :-
    must_be(nonvar, Step),
    (   Step = plan_step(_, _, _, _, _)
    ->  true
    ;   type_error(plan_step, Step)
    ).

		 /*******************************
		 *      ANSWERS IN ONE LINE     *
		 *******************************/

:- multifile user:portray/1.

%   The toplevel prints answers with portray(true): a plan, a partial plan
%   and a plan step print as one line; print_plan/1 and print_partial/1
%   print them in full.
user:portray(Plan) :-
    nonvar(Plan),
    Plan = plan(Partial, Result),
    is_partial(Partial),
    !,
    plan_summary(Partial, Result, S),
    format("~s", [S]).
user:portray(Partial) :-
    is_partial(Partial),
    !,
    partial_actions(Partial, As),
    length(As, NA),
    partial_ordering(Partial, Os),
    length(Os, NO),
    format("<partial plan: ~w actions, ~w orderings>", [NA, NO]).
user:portray(Step) :-
    nonvar(Step),
    Step = plan_step(N, Id, Action, _, Geo),
    integer(N),
    nonvar(Geo), Geo = geo(_, _),
    !,
    format("<step ~w ~q: ~W>", [N, Id, Action, [quoted(true), spacing(next_argument)]]).

plan_summary(Partial, Result, S) :-
    partial_actions(Partial, As),
    length(As, NA),
    (   Result = ur(aug(Steps, E, _, _, _, geo(Problem, _), _), _, _, _)
    ->  length(Steps, NS),
        format(string(S), "<plan ~w: ~w actions, ~w steps, ~w expected failures>",
               [Problem, NA, NS, E])
    ;   Result = no_instance(N, _, _)
    ->  format(string(S), "<plan: ~w actions, no executable instance among ~w examined>", [NA, N])
    ;   format(string(S), "<plan: ~w actions>", [NA])
    ).

is_partial(P) :-
    nonvar(P),
    P = partial(Actions, _, Net, _),
    is_list(Actions),
    nonvar(Net),
    Net = cms(_, _, _, _, _).

		 /*******************************
		 *        SCRIPTED SESSIONS     *
		 *******************************/

%!  batch_toplevel is det.
%
%   Read queries from user_input until end of file and answer each once:
%   its bindings (written as the toplevel writes them: quoted, portrayed,
%   a space after each argument's comma) and "true." or
%   "false.", or the error's message. Nothing is read between queries,
%   so a nondeterministic answer does not swallow the next query.

batch_toplevel :-
    repeat,
    prompt(_, ''),
    catch(read_term(user_input, Query, [variable_names(Bindings)]), E,
          ( print_message(error, E), fail )),
    (   Query == end_of_file
    ->  !
    ;   answer(Query, Bindings),
        fail
    ).

answer(Query, Bindings) :-
    catch(( call(user:Query) -> Result = true ; Result = false ),
          E, Result = error(E)),
    (   Result == true
    ->  print_bindings(Bindings)
    ;   Result == false
    ->  format("false.~n~n")
    ;   Result = error(E),
        print_message(error, E)
    ),
    flush_output.

print_bindings(Bindings) :-
    exclude([Name=_]>>sub_atom(Name, 0, _, _, '_'), Bindings, Shown),
    (   Shown == []
    ->  format("true.~n~n")
    ;   length(Shown, N),
        Opts = [quoted(true), portray(true), spacing(next_argument)],
        forall(nth1(I, Shown, Name = Value),
               (   I < N
               ->  format("~w = ~W,~n", [Name, Value, Opts])
               ;   format("~w = ~W.~n~n", [Name, Value, Opts])
               ))
    ).

		 /*******************************
		 *            HELP              *
		 *******************************/

%!  collect_docs is det.
%
%   Reload the planner's source files (prolog/*.pl, kb/templates/*.pl)
%   with PlDoc collecting their structured comments, so help/1 finds
%   them. Call it before loading problems: reloading kb.pl resets the
%   stored facts.

collect_docs :-
    use_module(library(pldoc), []),
    doc_collect(true),
    planner_files(Files),
    load_files(Files, [if(true), silent(true), imports([])]).

directory_files_pl(Dir, Files) :-
    directory_files(Dir, Names),
    include(prolog_file_name, Names, Pl),
    msort(Pl, Sorted),
    maplist(in_directory(Dir), Sorted, Files).

prolog_file_name(Name) :-
    file_name_extension(_, pl, Name).

in_directory(Dir, Name, File) :-
    atomic_list_concat([Dir, /, Name], File).

%!  spar_help(+Spec) is semidet.
%
%   Print the PlDoc comment of every planner predicate matching Spec
%   (Name/Arity or Name); fails if there is none. Without collect_docs/0
%   (a bare `swipl prolog/spar.pl`), the planner's sources are read for
%   their comments once, by library(prolog_xref), which stores them for
%   PlDoc without reloading anything.

spar_help(Spec) :-
    (   Spec = Name/Arity -> true ; Name = Spec ),
    must_be(atom, Name),
    use_module(library(pldoc), []),     % before doc_comment/4's own library
    (   spar_comments(Name/Arity, Cs)
    ->  true
    ;   store_docs,
        spar_comments(Name/Arity, Cs)
    ),
    forall(member(C, Cs), print_comment(C)).

%   spar_comments(+Name/Arity, -Comments): the comments of the planner's
%   predicates Name/Arity; of the one a user's query calls, if it has one
%   (plan_actions/2 of this module, not plan_state's of the same name).
spar_comments(Name/Arity, Cs) :-
    findall(M-C, ( doc_comment(M:Name/Arity, _, _, C),
                   spar_module(M) ),
            MCs0),
    sort(MCs0, MCs),
    MCs \== [],
    (   user_visible(Name/Arity, M0),
        memberchk(M0-_, MCs)
    ->  findall(C, member(M0-C, MCs), Cs)
    ;   findall(C, member(_-C, MCs), Cs1),
        sort(Cs1, Cs)
    ).

user_visible(Name/Arity, M) :-
    integer(Arity),
    functor(Head, Name, Arity),
    predicate_property(user:Head, imported_from(M)).

:- dynamic docs_stored/0.

store_docs :-
    docs_stored,
    !.
store_docs :-
    use_module(library(prolog_xref), [xref_source/2]),
    planner_files(Files),
    forall(member(F, Files),
           catch(xref_source(F, [comments(store), silent(true)]), _, true)),
    assertz(docs_stored).

planner_files(Files) :-
    absolute_file_name(spar(prolog), Dir, [file_type(directory)]),
    absolute_file_name(spar(kb/templates), Templates, [file_type(directory)]),
    directory_files_pl(Dir, Own),
    directory_files_pl(Templates, Tpl),
    append(Own, Tpl, Files).

spar_module(M) :-
    module_property(M, file(F)),
    absolute_file_name(spar(.), Root, [file_type(directory)]),
    sub_atom(F, 0, _, _, Root).

print_comment(C) :-
    split_string(C, "\n", "", Lines),
    forall(member(L, Lines),
           (   string_concat("%!", Rest, L)
           ->  format(" ~s~n", [Rest])
           ;   string_concat("%", Rest, L)
           ->  format("~s~n", [Rest])
           ;   format("~s~n", [L])
           )),
    nl.

:- multifile user:help/1.
:- dynamic user:help/1.

%   help(+Spec): the planner's own PlDoc first, then SWI-Prolog's
%   library(help) where it is installed.
user:help(Spec) :-
    (   catch(spar_help(Spec), _, fail)
    ->  true
    ;   exists_source(library(help))
    ->  use_module(library(help), []),
        help:help(Spec)
    ;   format("No documentation for ~q (SWI-Prolog's manual is not installed).~n", [Spec])
    ).
