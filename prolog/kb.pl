/*  spar-py: the knowledge-base facts of the loaded problem (module kb).

    The Python loader (src/spar_py/kb.py) validates the YAML files and sends
    the facts here through foreign:spar_load_facts/1; they replace the facts of
    any earlier problem. Shapes follow the paper:

      pose(Obj, Label, rfaces(Fs), ofaces(Fs), tm(Rows))            Fig. 18
      grasp(Obj, Label, gfaces(Fs), ofaces(Fs),
            eulerxyz(X,Y,Z,Phi,Theta,Psi), width(W))                Fig. 19
      position(Name, Obj, Label, tm(Rows))     absolute initial positions
      position_class(Label, PoseLabel)         Sec. 5.2.3, computed at load
      object/1, face/2, initial/1, goal/1, transform/2, vector/2, problem/1
*/
:- module(kb, [replace_facts/1]).
:- use_module(library(error)).
:- use_module(library(apply)).

:- dynamic
    problem/1, object/1, face/2, pose/5, grasp/6, position/4,
    position_class/2, initial/1, goal/1, transform/2, vector/2.

%!  kb_predicate(?Name, ?Arity) is nondet.
%
%   The predicates a knowledge base defines.

kb_predicate(problem, 1).        kb_predicate(object, 1).
kb_predicate(face, 2).           kb_predicate(pose, 5).
kb_predicate(grasp, 6).          kb_predicate(position, 4).
kb_predicate(position_class, 2). kb_predicate(initial, 1).
kb_predicate(goal, 1).           kb_predicate(transform, 2).
kb_predicate(vector, 2).

%!  replace_facts(+Facts:list) is det.
%
%   Retract every knowledge-base fact and assert Facts instead.
%
%   @error domain_error(kb_fact, F) if an element is not a KB fact.

replace_facts(Facts) :-
    must_be(list, Facts),
    maplist(check_fact, Facts),
    forall(kb_predicate(N, A), (functor(H, N, A), retractall(H))),
    maplist(assertz, Facts).

check_fact(F) :-
    (   callable(F), functor(F, N, A), kb_predicate(N, A)
    ->  true
    ;   domain_error(kb_fact, F)
    ).
