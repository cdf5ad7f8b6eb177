/*  spar-py: the one place where the planner calls Python (janus py_call/2,3).

    Everything numeric or symbolic (inverse kinematics, CasADi transforms,
    SUP/INF) lives in src/spar_py/ and is reached from here, through the
    Python-side bridge module spar_py.planning.engine. Other Prolog modules call
    these predicates and never py_call/2,3 themselves.
*/
:- module(foreign,
          [ arc_pairs/5,             % +Constraint, +Objects, +GLabels, +PLabels, -Pairs
            arc_pairs/7,             % +Problem, +Rule, +Constraint, +Objects, +GLabels, +PLabels, -Pairs
            py_bridge/2,             % +Call, -Result (for phase 2)
            spar_load_facts/1,       % +Data (from Python)
            load_problem_file/2,     % +File, -Problem
            unload_problem_cell/1,   % +Problem
            data_term/2,             % +Data, -Term
            term_data/2,             % +Term, -Data
            error_info/2             % +Error, -Info
          ]).
:- use_module(kb, []).
:- use_module(library(janus)).
:- use_module(library(error)).
:- use_module(library(apply)).

%!  arc_pairs(+Problem, +Rule, +Constraint, +Objects, +GraspLabels, +PosLabels, -Pairs) is det.
%
%   All pairs Grasp/Position of the two label sets that satisfy Constraint
%   in the loaded problem Problem, computed in one Python call (Sec. 5.2.4):
%
%     - Constraint = reachable, Objects = Obj: conditions 1 and 2 for an
%       absolute position label (tr1), condition 1 only for a stable pose
%       label (p2P1);
%     - Constraint = mate_reachable(Ta), Objects = Held-Fixed: condition 2 for
%       T = T_O Ta T_g, Ta the name of a kb:transform/2.
%
%   Rule says how a stable-pose label counts for condition 2: reachable
%   (some placement in the free table regions reaches it) or paper (assumed
%   reachable, Sec. 5.2.4). Pairs is a list of GraspLabel/PosLabel, as the
%   paper's Fig. 25. Phase 1 passes arc_pairs(Problem, Rule) as its oracle.
%
%   @error type_error(list, X) if a label set is not a list.

arc_pairs(Problem, Rule, Constraint, Objects, GLabels, PLabels, Pairs) :-
    must_be(atom, Problem),
    must_be(oneof([reachable, paper]), Rule),
    must_be(list(atom), GLabels),
    must_be(list(atom), PLabels),
    arc_call(Constraint, Objects, GLabels, PLabels, Call0),
    Call0 =.. [F|Args],
    Call =.. [F, Problem, Rule|Args],
    py_call('spar_py.planning.engine':Call, Raw),
    maplist(pair_term, Raw, Pairs).

%!  arc_pairs(+Constraint, +Objects, +GraspLabels, +PosLabels, -Pairs) is det.
%
%   arc_pairs/7 for the problem in scope (kb:with_problem/2) with the
%   default rule, reachable.

arc_pairs(Constraint, Objects, GLabels, PLabels, Pairs) :-
    kb:problem_in_scope(Problem),
    arc_pairs(Problem, reachable, Constraint, Objects, GLabels, PLabels, Pairs).

arc_call(reachable, Obj, Gs, Ps, arc_pairs(reachable, [Obj], Gs, Ps, none)) :-
    !,
    must_be(atom, Obj).
arc_call(mate_reachable(Ta), Held-Fixed, Gs, Ps,
         arc_pairs(mate_reachable, [Held, Fixed], Gs, Ps, Ta)) :-
    !,
    must_be(atom, Held), must_be(atom, Fixed), must_be(atom, Ta).
arc_call(C, _, _, _, _) :-
    domain_error(geometric_constraint, C).

pair_term([G, P], G/P).

%!  py_bridge(+Call, -Result) is det.
%
%   Call a function of spar_py.planning.engine for phase 2: uncertainty.pl calls
%   evaluate(Problem, Steps, Sources, GivenUp, Sensing) once per run of a
%   plan instance; Result is plain data (dicts, lists, strings, numbers),
%   no Python object.
%
%   @error type_error(callable, Call) if Call is not a term.

py_bridge(Call, Result) :-
    must_be(callable, Call),
    py_call('spar_py.planning.engine':Call, Result).

%!  spar_load_facts(+Data:list) is det.
%
%   Replace the knowledge base by the facts Data sent from Python
%   (spar_py.kb.facts/1: tuples for compounds, strings for atoms).

spar_load_facts(Data) :-
    must_be(list, Data),
    maplist(data_term, Data, Facts),
    kb:replace_facts(Facts).

%!  load_problem_file(+File, -Problem) is det.
%
%   Load the problem file File through the Python loader (spar_py.kb,
%   every check applies): its facts replace those of the problem of the
%   same name, and Python keeps its cell for the calls about Problem.
%
%   @error spar_error(Message) if the file is not a valid problem (the
%          loader's one-line message).

load_problem_file(File, Problem) :-
    atom_string(File, FileS),
    catch(py_call('spar_py.planning.engine':load_problem_file(FileS), [Name, Data]), E,
          spar_error(E)),
    atom_string(Problem, Name),
    spar_load_facts(Data).

%!  unload_problem_cell(+Problem) is det.
%
%   Forget Problem on both sides: its facts and its Python cell.

unload_problem_cell(Problem) :-
    kb:unload_facts(Problem),
    py_call('spar_py.planning.engine':forget_cell(Problem)).

%   A SparError raised by the loader becomes error(spar_error(Msg), _),
%   printed as its one-line message.
spar_error(error(python_error(_, V), _)) :-
    py_call('spar_py.planning.engine':is_spar_error(V), @(true)),
    !,
    py_call(str(V), Msg),
    throw(error(spar_error(Msg), _)).
spar_error(E) :-
    throw(E).

:- multifile prolog:error_message//1.
prolog:error_message(spar_error(Msg)) -->
    [ '~w'-[Msg] ].

%!  data_term(+Data, -Term) is det.
%
%   Turn janus data into a term: a string becomes an atom, a Python tuple
%   (functor, Arg...) (janus: -(F, A1, ...)) a compound, a list a list.
%
%   @error type_error(spar_data, D) for anything else.

data_term(D, T) :-
    (   string(D) -> atom_string(T, D)
    ;   number(D) -> T = D
    ;   atom(D) -> T = D
    ;   is_list(D) -> maplist(data_term, D, T)
    ;   compound(D), compound_name_arguments(D, -, [F0|As0]), As0 \== []
    ->  data_term(F0, F), must_be(atom, F),
        maplist(data_term, As0, As),
        compound_name_arguments(T, F, As)
    ;   type_error(spar_data, D)
    ).

%!  error_info(+Error, -Info:dict) is det.
%
%   What the Python side needs to raise the right exception for a Prolog
%   exception Error (spar_py.planning.engine, the one place that maps them):
%
%     - _{kind: timeout} for time_limit_exceeded;
%     - _{kind: interrupted} for an abort (unwind(abort), '$aborted');
%     - _{kind: python, class: C, value: V} for an exception a Python
%       function raised inside py_call (V is the Python exception object);
%     - _{kind: prolog, formal: F, message: M} otherwise: F the formal
%       term as data (term_data/2), M the first line of Prolog's message.

error_info(E, _{kind: timeout}) :-
    E == time_limit_exceeded, !.
error_info(E, _{kind: interrupted}) :-
    ( E == '$aborted' ; E == unwind(abort) ), !.
error_info(E, _{kind: python, class: C, value: V}) :-
    subsumes_term(error(python_error(_, _), _), E), !,
    E = error(python_error(C, V), _).
error_info(E, _{kind: prolog, formal: F, message: M}) :-
    (   E = error(Formal, _) -> true ; Formal = E ),
    term_data(Formal, F),
    (   catch(message_text(E, M0), _, fail)
    ->  true
    ;   format(string(M0), "~q", [E])
    ),
    split_string(M0, "\n", " \t", Lines),
    exclude(==(""), Lines, [M|_]).

message_text(E, S) :-
    '$messages':translate_message(E, Lines, []),
    with_output_to(string(S), print_message_lines(current_output, '', Lines)).

%!  term_data(+Term, -Data) is det.
%
%   Term as janus data, the inverse of data_term/2 for ground terms: an
%   atom becomes a string, a number stays, a string S becomes
%   _{string: S}, a list a list, a compound _{functor: F, args: [...]}, a
%   variable _{var: Name}. Plans cross to Python this way, not as text.

term_data(T, D) :-
    (   var(T) -> format(string(N), "~p", [T]), D = _{var: N}
    ;   atom(T) -> atom_string(T, D)
    ;   number(T) -> D = T
    ;   string(T) -> D = _{string: T}
    ;   is_list(T) -> maplist(term_data, T, D)
    ;   compound_name_arguments(T, F, As),
        atom_string(F, FS),
        maplist(term_data, As, AD),
        D = _{functor: FS, args: AD}
    ).
