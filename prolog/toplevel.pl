/*  spar-py: the Prolog toplevel of `spar repl` (load problems, print plans,
    scripted sessions).

    What a user at the toplevel needs beyond spar.pl's entry points:

      - load_problem/1,2 reads a problem file through the Python loader
        (every KB check applies) and keeps it loaded beside the others;
        loaded_problems/1 lists them, unload_problem/1 forgets one;
      - print_plan/1 prints a plan/2 answer, both phases; answers print
        plan terms as print_plan/1 and partial plans as print_partial/1
        do (a portray/1 hook), not as several kB of term;
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
:- use_module(partial_plan, [print_partial/1]).
:- use_module(uncertainty, [print_ur/1]).
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

print_plan(plan(Partial, Result)) :-
    print_partial(Partial),
    print_ur(Result).

:- multifile user:portray/1.

%   The toplevel prints answers with portray(true): a plan prints as
%   print_plan/1 shows it, a partial plan as print_partial/1.
user:portray(Plan) :-
    nonvar(Plan),
    Plan = plan(Partial, _),
    is_partial(Partial),
    !,
    nl,
    print_plan(Plan).
user:portray(Partial) :-
    is_partial(Partial),
    !,
    nl,
    print_partial(Partial).

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
%   its bindings (printed as the toplevel prints them) and "true." or
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
        forall(nth1(I, Shown, Name = Value),
               (   I < N
               ->  format("~w = ~p,~n", [Name, Value])
               ;   format("~w = ~p.~n~n", [Name, Value])
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
    module_property(spar_toplevel, file(Me)),
    file_directory_name(Me, Dir),
    atom_concat(Dir, '/../kb/templates', Templates),
    directory_files_pl(Dir, Own),
    directory_files_pl(Templates, Tpl),
    append(Own, Tpl, Files),
    load_files(Files, [if(true), silent(true)]).

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
%   (Name/Arity or Name); fails if there is none.

spar_help(Spec) :-
    (   Spec = Name/Arity -> true ; Name = Spec ),
    must_be(atom, Name),
    use_module(library(pldoc), []),     % before doc_comment/4's own library
    findall(C, ( doc_comment(M:Name/Arity, _, _, C),
                 spar_module(M) ),
            Cs0),
    sort(Cs0, Cs),
    Cs \== [],
    forall(member(C, Cs), print_comment(C)).

spar_module(M) :-
    module_property(M, file(F)),
    module_property(spar_toplevel, file(Me)),
    file_directory_name(Me, Dir),
    file_directory_name(Dir, Root),
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
