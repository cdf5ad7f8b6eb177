/*  spar-py: the knowledge bases of the loaded problems (module kb).

    The Python loader (package spar_py.kb) validates the YAML files and sends
    a problem's facts here through foreign:spar_load_facts/1. Several
    problems may be loaded at once: each fact is stored under its problem's
    name, and loading a problem again replaces only that problem's facts.
    Shapes follow the paper:

      pose(Obj, Label, rfaces(Fs), ofaces(Fs), tm(Rows))            Fig. 18
      grasp(Obj, Label, gfaces(Fs), ofaces(Fs),
            eulerxyz(X,Y,Z,Phi,Theta,Psi), width(W))                Fig. 19
      position(Name, Obj, Label, tm(Rows))     absolute initial positions
      position_class(Label, PoseLabel)         Sec. 5.2.3, computed at load
      object/1, face/2, initial/1, goal/1, transform/2, vector/2, problem/1
      turn(Ta, Turn, HolePoses)   a derived T_a's turns about the hole's axis
                                  (goal assembled(Peg, Hole)), in order: the
                                  goal names Ta, an assemble may use any Turn
                                  (a transform/2), the hole part then resting
                                  in one of HolePoses (the mated peg clears
                                  the table in them)
      mate_grasps(Ta, Peg, Grasps)  the grasps of Peg usable for the goal's
                                  assemble at Ta, decided by geometry (the
                                  hand holds only what stays out of the hole)
      precedence(P, Q, Reason)    a product's part P must be inserted
                                  before part Q (Q in place would block
                                  P's insertion; Reason a string)
      mates(Part, Pairs)          the mates and seats a product part's
                                  insertion can make, Name-Other (Name
                                  a string, PART.F->PART.G; Other the
                                  mate's other part): it makes one when
                                  Other is in place before it

    The planner reads them through the accessors of the same names
    (kb:grasp/6, ...), which answer for the problem in scope: a planning
    run wraps its work in with_problem/2, which puts the problem's name in
    a backtrackable, thread-local global variable for the duration of the
    goal (until backtracking undoes it; a query's end does). Where no
    with_problem/2 ran, the accessors answer for the only loaded problem,
    and raise existence_error(problem_in_scope, kb) when several (or none)
    are loaded. Two threads planning two problems each see their own.
*/
:- module(kb,
          [ replace_facts/1,        % +Facts
            unload_facts/1,         % +Problem
            loaded_problem/1,       % ?Problem
            with_problem/2,         % +Problem, :Goal
            problem_in_scope/1,     % -Problem
            % the accessors: the facts of the problem in scope
            problem/1,              % ?Problem
            object/1,               % ?Object
            face/2,                 % ?Object, ?Face
            pose/5,                 % ?Object, ?Label, ?RFaces, ?OFaces, ?Tm
            grasp/6,                % ?Object, ?Label, ?GFaces, ?OFaces, ?Euler, ?Width
            position/4,             % ?Name, ?Object, ?Label, ?Tm
            position_class/2,       % ?Label, ?PoseLabel
            initial/1,              % ?Condition
            goal/1,                 % ?Goal
            transform/2,            % ?Name, ?Tm
            vector/2,               % ?Name, ?XYZ
            turn/3,                 % ?Ta, ?Turn, ?HolePoses
            mate_grasps/3,          % ?Ta, ?Peg, ?Grasps
            precedence/3,           % ?Part, ?Later, ?Reason
            mates/2                 % ?Part, ?Pairs
          ]).
:- use_module(library(error)).
:- use_module(library(apply)).
:- use_module(library(lists)).

:- meta_predicate with_problem(+, 0).

%!  kb_predicate(?Name, ?Arity) is nondet.
%
%   The predicates a knowledge base defines.

kb_predicate(problem, 1).        kb_predicate(object, 1).
kb_predicate(face, 2).           kb_predicate(pose, 5).
kb_predicate(grasp, 6).          kb_predicate(position, 4).
kb_predicate(position_class, 2). kb_predicate(initial, 1).
kb_predicate(goal, 1).           kb_predicate(transform, 2).
kb_predicate(vector, 2).         kb_predicate(turn, 3).
kb_predicate(mate_grasps, 3).
kb_predicate(precedence, 3).     kb_predicate(mates, 2).

%   stored(?Fact, ?Problem, ?Stored): Stored is Fact as kept for Problem,
%   '$Name'(Problem, Args...).
stored(Fact, Problem, Stored) :-
    Fact =.. [Name|Args],
    atom_concat('$', Name, SName),
    Stored =.. [SName, Problem|Args].

%   One dynamic predicate '$Name'/Arity+1 per knowledge-base predicate, and
%   an accessor Name/Arity reading it for the problem in scope.
term_expansion(kb_storage, Clauses) :-
    findall(Clause, storage_clause(Clause), Clauses).

storage_clause((:- dynamic(SName/A1))) :-
    kb_predicate(N, A),
    atom_concat('$', N, SName),
    A1 is A + 1.
storage_clause((Head :- problem_in_scope(P), Stored)) :-
    kb_predicate(N, A),
    functor(Head, N, A),
    stored(Head, P, Stored).

%!  problem(?Problem) is semidet.
%!  object(?Object) is nondet.
%!  face(?Object, ?Face) is nondet.
%!  pose(?Object, ?Label, ?RFaces, ?OFaces, ?Tm) is nondet.
%!  grasp(?Object, ?Label, ?GFaces, ?OFaces, ?Euler, ?Width) is nondet.
%!  position(?Name, ?Object, ?Label, ?Tm) is nondet.
%!  position_class(?Label, ?PoseLabel) is nondet.
%!  initial(?Condition) is nondet.
%!  goal(?Goal) is nondet.
%!  transform(?Name, ?Tm) is nondet.
%!  vector(?Name, ?XYZ) is nondet.
%!  turn(?Ta, ?Turn, ?HolePoses) is nondet.
%!  mate_grasps(?Ta, ?Peg, ?Grasps) is nondet.
%!  precedence(?Part, ?Later, ?Reason) is nondet.
%!  mates(?Part, ?Pairs) is nondet.
%
%   The accessors: the facts of the problem in scope (problem_in_scope/1),
%   in the shapes this file's header gives, in load order. Each reads the
%   dynamic predicate '$Name'/Arity+1 that replace_facts/1 fills.
%   Other modules call them qualified (kb:grasp/6), so a reader sees
%   where the fact comes from.
%
%   @error existence_error(problem_in_scope, kb) outside with_problem/2
%          with no problem or several loaded.

kb_storage.

%!  replace_facts(+Facts:list) is det.
%
%   Load a problem: Facts must hold exactly one problem(Name) fact; every
%   fact stored for Name before is retracted and Facts asserted instead.
%   Other loaded problems are untouched.
%
%   @error domain_error(kb_fact, F) if an element is not a KB fact.
%   @error domain_error(kb_facts_with_one_problem, Facts) if Facts do not
%          name exactly one problem.

replace_facts(Facts) :-
    must_be(list, Facts),
    maplist(check_fact, Facts),
    (   findall(P, member(problem(P), Facts), [Problem]),
        atom(Problem)
    ->  true
    ;   domain_error(kb_facts_with_one_problem, Facts)
    ),
    unload_facts(Problem),
    forall(member(F, Facts), (stored(F, Problem, S), assertz(S))).

check_fact(F) :-
    (   callable(F), functor(F, N, A), kb_predicate(N, A)
    ->  true
    ;   domain_error(kb_fact, F)
    ).

%!  unload_facts(+Problem:atom) is det.
%
%   Retract every fact stored for Problem (nothing if it is not loaded).

unload_facts(Problem) :-
    must_be(atom, Problem),
    forall(kb_predicate(N, A),
           ( functor(H, N, A), stored(H, Problem, S), retractall(S) )).

%!  loaded_problem(?Problem) is nondet.
%
%   Problem is a loaded problem (in load order).

loaded_problem(Problem) :-
    '$problem'(Problem, Problem).

%!  with_problem(+Problem, :Goal) is nondet.
%
%   Call Goal with the knowledge base of Problem in scope for the
%   accessors (kb:goal/1, kb:grasp/6, ...).
%
%   @error existence_error(problem, Problem) if Problem is not loaded.

with_problem(Problem, Goal) :-
    must_be(atom, Problem),
    (   loaded_problem(Problem)
    ->  true
    ;   existence_error(problem, Problem)
    ),
    b_setval(spar_problem, Problem),
    call(Goal).

%!  problem_in_scope(-Problem) is det.
%
%   The problem with_problem/2 put in scope; where none did, the only
%   loaded problem (so a toplevel or a test with one problem loaded can
%   ask kb:grasp/6 directly).
%
%   @error existence_error(problem_in_scope, kb) outside with_problem/2
%          with no problem or several loaded.

problem_in_scope(Problem) :-
    (   nb_current(spar_problem, P0), atom(P0), P0 \== []
    ->  Problem = P0
    ;   findall(P, loaded_problem(P), [P1])
    ->  Problem = P1
    ;   existence_error(problem_in_scope, kb)
    ).
