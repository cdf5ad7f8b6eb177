/*  Tests of the planner's module structure: the modules of the .pl files
    in prolog/ and kb/templates/, with an arc M1 -> M2 when M1 imports M2
    (use_module, reexport) or calls into it by a qualified goal M2:G in a
    clause body, form a graph without cycles, so each can be read, loaded
    and tested with only the modules below it.

    The graph comes from library(prolog_xref): xref_uses_file/3 gives the
    imports, xref_called/3 the qualified calls (meta-calls included:
    limit/2, phrase/3, findall/3, ...).

    A qualified call M:G into a planner module is a call of one of M's
    exports (module kb's accessors, say, kb:grasp/6): for module kb this
    is checked over the planner's files and the tests' (unexported_calls/3).

    swipl -g run_tests -t halt tests/prolog/modules.plt
*/
:- use_module(library(plunit)).
:- use_module('../../prolog/spar_paths', []).  % spar(...) paths, for xref
:- use_module(library(prolog_xref)).
:- use_module(library(ugraphs)).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(yall)).
:- use_module(library(error)).

:- prolog_load_context(directory, Dir),
   asserta(modules_test_dir(Dir)).

%   repo_root(-Root): the checkout this test file belongs to.
repo_root(Root) :-
    modules_test_dir(Dir),
    atomic_list_concat([Dir, '/../..'], Root0),
    absolute_file_name(Root0, Root, [file_type(directory)]).

%!  planner_files(+Root, -Files) is det.
%
%   The planner's own source files under Root: prolog/*.pl and
%   kb/templates/*.pl, as absolute paths.

planner_files(Root, Files) :-
    atomic_list_concat([Root, '/prolog/*.pl'], P1),
    atomic_list_concat([Root, '/kb/templates/*.pl'], P2),
    expand_file_name(P1, F1),
    expand_file_name(P2, F2),
    append(F1, F2, Fs0),
    maplist([F, A]>>absolute_file_name(F, A), Fs0, Fs),
    sort(Fs, Files).

%!  module_graph(+Root, -Graph) is det.
%
%   Graph is the ugraph of the planner's modules under Root: an arc M1-M2
%   for every import of M2's file by M1's file and every qualified call
%   M2:G made from M1, both modules the planner's own.

module_graph(Root, Graph) :-
    planner_files(Root, Files),
    files_module_graph(Files, Graph).

%   files_module_graph(+Files, -Graph): module_graph/2 of the module files
%   Files.

files_module_graph(Files, Graph) :-
    maplist([F]>>xref_source(F, [silent(true)]), Files),
    findall(F-M, ( member(F, Files), xref_module(F, M) ), FileModules),
    pairs_values(FileModules, Modules),
    findall(M1-M2,
            ( member(F1-M1, FileModules),
              module_dependency(F1, M1, FileModules, M2),
              M2 \== M1 ),
            Arcs0),
    sort(Arcs0, Arcs),
    vertices_edges_to_ugraph(Modules, Arcs, Graph).

module_dependency(File, _, FileModules, M2) :-
    xref_uses_file(File, _Spec, Path),
    memberchk(Path-M2, FileModules).
module_dependency(File, _, FileModules, M2) :-
    xref_called(File, Called, _By),
    nonvar(Called),
    Called = M2:_,
    atom(M2),
    memberchk(_-M2, FileModules).

%!  test_files(+Root, -Files) is det.
%
%   The plunit files under Root's tests/prolog (the bare ones too) and
%   their fixtures, as absolute paths.

test_files(Root, Files) :-
    findall(File,
            ( member(P, [ '/tests/prolog/*.plt', '/tests/prolog/bare/*.plt',
                          '/tests/prolog/fixtures/*.pl' ]),
              atomic_list_concat([Root, P], Pattern),
              expand_file_name(Pattern, Fs),
              member(F, Fs),
              absolute_file_name(F, File) ),
            Files0),
    sort(Files0, Files).

%!  unexported_calls(+Files, +Module, -Calls) is det.
%
%   Calls are File-Module:Name/Arity, sorted, for every qualified call
%   Module:G in Files (meta-calls included, as xref_called/3 sees them)
%   of a predicate that Module's file, one of Files, does not export.
%
%   @error existence_error(module_file, Module) if no file of Files is
%          module Module.

unexported_calls(Files, Module, Calls) :-
    maplist([F]>>xref_source(F, [silent(true)]), Files),
    (   member(MFile, Files),
        xref_module(MFile, Module)
    ->  true
    ;   existence_error(module_file, Module)
    ),
    findall(File-Module:Name/Arity,
            ( member(File, Files),
              xref_called(File, Called, _By),
              nonvar(Called),
              Called = M:Goal,
              M == Module,
              callable(Goal),
              functor(Goal, Name, Arity),
              functor(Head, Name, Arity),
              \+ xref_exported(MFile, Head) ),
            Calls0),
    sort(Calls0, Calls).

%!  module_cycles(+Graph, -Pairs) is det.
%
%   Pairs are the arcs M1-M2 of Graph that lie on a cycle (M1 is reachable
%   from M2): the arcs to undo.

module_cycles(Graph, Pairs) :-
    transitive_closure(Graph, Closure),
    findall(M1-M2,
            ( member(M1-Ns, Graph), member(M2, Ns),
              memberchk(M2-Reach, Closure), memberchk(M1, Reach) ),
            Pairs).

:- begin_tests(planner_modules).

test(every_file_a_module, Missing == []) :-
    repo_root(Root),
    planner_files(Root, Files),
    maplist(xref_source, Files),
    exclude([F]>>xref_module(F, _), Files, Missing).

%   Each file's module is named as the file (prolog/spar_toplevel.pl is
%   module spar_toplevel), so a module's name finds its file.
test(module_named_as_its_file, Misnamed == []) :-
    repo_root(Root),
    planner_files(Root, Files),
    maplist(xref_source, Files),
    findall(File-M,
            ( member(File, Files),
              xref_module(File, M),
              file_base_name(File, Base),
              \+ file_name_extension(M, pl, Base) ),
            Misnamed).

test(graph_has_imports_and_qualified_calls) :-
    repo_root(Root),
    module_graph(Root, G),
    memberchk(spar-Spar, G),
    memberchk(goals, Spar),                 % use_module(goals, [...])
    memberchk(uncertainty-Unc, G),
    memberchk(spar_sensing, Unc),           % spar_sensing:remedy_rule/3, ...
    memberchk(goals-Goals, G),
    memberchk(spar_actions, Goals).

%   Two modules in temporary files, a qualified call from each into the
%   other and no import: the graph has both arcs, and the cycle is found.
test(qualified_calls_make_a_cycle, [ Graph == [qa-[qb], qb-[qa]],
                                     Cycles == [qa-qb, qb-qa],
                                     cleanup(maplist(delete_file, [A, B])) ]) :-
    tmp_file_stream(text, A, SA),
    format(SA, ":- module(qa, [a/0]).~na :- qb:b.~n", []),
    close(SA),
    tmp_file_stream(text, B, SB),
    format(SB, ":- module(qb, [b/0]).~nb :- true.~nc :- findall(x, qa:a, _).~n", []),
    close(SB),
    files_module_graph([A, B], Graph),
    module_cycles(Graph, Cycles).

test(no_cycle, Cycles == []) :-
    repo_root(Root),
    module_graph(Root, G),
    module_cycles(G, Cycles),
    (   Cycles == []
    ->  assertion(top_sort(G, _))
    ;   true
    ).

%   Every call kb:G in the planner and its tests (kb:grasp/6, kb:initial/1,
%   kb:replace_facts/1, ...) is of an export of kb.pl. Python's calls are
%   checked by tests/test_kb_exports.py.
test(kb_calls_are_to_exports, Calls == []) :-
    repo_root(Root),
    planner_files(Root, Planner),
    test_files(Root, Tests),
    append(Planner, Tests, Files),
    unexported_calls(Files, kb, Calls).

%   A module exporting a/0 and a caller of qk:a, qk:b and (in a findall)
%   qk:c(_): the two unexported ones are found.
test(unexported_calls_found, [ Calls == [B-qk:b/0, B-qk:c/1],
                               cleanup(maplist(delete_file, [A, B])) ]) :-
    tmp_file_stream(text, A, SA),
    format(SA, ":- module(qk, [a/0]).~na.~nb.~nc(_).~n", []),
    close(SA),
    tmp_file_stream(text, B, SB),
    format(SB, ":- module(qcaller, [d/0]).~nd :- qk:a, qk:b, findall(X, qk:c(X), _).~n", []),
    close(SB),
    unexported_calls([A, B], qk, Calls).

:- end_tests(planner_modules).
