/*  spar-py: the one place where the planner calls Python (janus py_call/2,3).

    Everything numeric or symbolic (inverse kinematics, CasADi transforms,
    SUP/INF) lives in src/spar_py/ and is reached from here, through the
    Python-side bridge module spar_py.engine. Other Prolog modules call
    these predicates and never py_call/2,3 themselves.
*/
:- module(foreign,
          [ arc_pairs/5,             % +Constraint, +Objects, +GLabels, +PLabels, -Pairs
            py_bridge/2,             % +Call, -Result (for phase 2)
            spar_load_facts/1,       % +Data (from Python)
            data_term/2              % +Data, -Term
          ]).
:- use_module(kb, []).
:- use_module(library(janus)).
:- use_module(library(error)).
:- use_module(library(apply)).

%!  arc_pairs(+Constraint, +Objects, +GraspLabels, +PosLabels, -Pairs) is det.
%
%   All pairs Grasp/Position of the two label sets that satisfy Constraint,
%   computed in one Python call (Sec. 5.2.4):
%
%     - Constraint = reachable, Objects = Obj: conditions 1 and 2 for an
%       absolute position label (tr1), condition 1 only for a stable pose
%       label (p2P1);
%     - Constraint = mate_reachable(Ta), Objects = Held-Fixed: condition 2 for
%       T = T_O Ta T_g, Ta the name of a kb:transform/2.
%
%   Pairs is a list of GraspLabel/PosLabel, as the paper's Fig. 25.
%
%   @error type_error(list, X) if a label set is not a list.

arc_pairs(Constraint, Objects, GLabels, PLabels, Pairs) :-
    must_be(list(atom), GLabels),
    must_be(list(atom), PLabels),
    arc_call(Constraint, Objects, GLabels, PLabels, Call),
    py_call('spar_py.engine':Call, Raw),
    maplist(pair_term, Raw, Pairs).

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
%   Call a function of spar_py.engine (phase 2: world state, UR constraints).

py_bridge(Call, Result) :-
    py_call('spar_py.engine':Call, Result).

%!  spar_load_facts(+Data:list) is det.
%
%   Replace the knowledge base by the facts Data sent from Python
%   (spar_py.kb.facts/1: tuples for compounds, strings for atoms).

spar_load_facts(Data) :-
    must_be(list, Data),
    maplist(data_term, Data, Facts),
    kb:replace_facts(Facts).

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
