/*  spar-py: phase 2, uncertainty-reduction planning (Secs. 2, 3.3, 4.3).

    Plan instances (a solution of the constraint network x a linearisation of
    the ordering graph) are generated lazily from the phase-1 partial plan.
    Each is checked action by action with the world's uncertainty propagated
    forward (the numbers and symbols are Python's, reached through foreign.pl);
    an unmet uncertainty-reduction precondition triggers, in order:

      1. pickup(Obj, G): a dense_range_scan(Obj) just before the pickup;
         assemble(O1, O2, ...): two scans, of O1 and O2, just before the
         action that establishes holding(O1, _) (Sec. 4.3);
      2. a squeeze of the object on the table, spliced in just before that
         same pickup (assemble only: Sec. 4.3);
      3. otherwise the error count + 1, a verification action (Fig. 12) and a
         local recovery plan (Fig. 13) for the action.

    The first instance with no error wins; otherwise the one with the fewest
    errors among at most max_instances(Cap) examined.
*/
:- module(uncertainty,
          [ phase2/4,              % +Problem, +Partial, +Options, -Result
            check_instance/5,      % +Problem, +Steps, +Sources, +Bound, -Augmented
            instance_steps/3,      % +Instance, -Steps, -Bindings
            instance_sources/2,    % +Instance, -Sources
            ur_dict/2,             % +Result, -Dict
            print_ur/1             % +Result
          ]).
:- use_module(library(apply)).
:- use_module(library(lists)).
:- use_module(library(option)).
:- use_module(library(error)).
:- use_module(library(yall)).
:- use_module(foreign, [py_bridge/2]).
:- use_module(spar_defaults, [default_option/2]).
:- use_module('../kb/templates/sensing', []).

%!  phase2(+Problem, +Partial, +Options, -Result) is det.
%
%   Phase 2 of the loaded problem Problem on its phase-1 plan Partial.
%   Result = ur(Best, Examined, Cap, Complete), or no_instance(Examined, Cap,
%   Complete) when no instance could be executed at all (every one needed
%   a put-down with no reachable placement). Best is an augmented instance
%   aug(Steps, ErrorCount, Verifications, Recoveries, Verdicts, Geometry,
%   Bindings) (see check_instance/2); Examined the instances checked;
%   Complete true if the partial plan has no further instance.
%   Options: max_instances(Cap) (default: spar_defaults:default_option/2).

phase2(Problem, Partial, Options, Result) :-
    must_be(atom, Problem),
    default_option(max_instances, Cap0),
    option(max_instances(Cap), Options, Cap0),
    must_be(positive_integer, Cap),
    State = best(none, inf, 0, false),
    (   once(( limit(Cap, spar:partial_instances(Partial, Instance)),
               examine(Problem, Instance, State, Aug),
               arg(2, Aug, 0)
             ))
    ->  true
    ;   arg(3, State, N), N < Cap
    ->  nb_setarg(4, State, true)
    ;   true
    ),
    State = best(Best, _, Examined, Complete),
    (   Best == none
    ->  Result = no_instance(Examined, Cap, Complete)
    ;   Result = ur(Best, Examined, Cap, Complete)
    ).

examine(Problem, Instance, State, Aug) :-
    arg(3, State, N0), N is N0 + 1, nb_setarg(3, State, N),
    instance_steps(Instance, Steps, Bindings),
    instance_sources(Instance, Sources),
    arg(2, State, BestE),
    check_instance(Problem, Steps, Sources, BestE, aug(S, E, V, R, C, G)),
    Aug = aug(S, E, V, R, C, G, Bindings),
    (   (BestE == inf ; E < BestE)
    ->  nb_setarg(1, State, Aug), nb_setarg(2, State, E)
    ;   true
    ).

%!  instance_steps(+Instance, -Steps, -Bindings) is det.
%
%   The steps step(Id, Action) of a plan instance (spar:partial_instances/2)
%   in execution order, and its bindings Var = Label.

instance_steps(instance(Actions, Bindings), Steps, Bindings) :-
    maplist([action(Id, T, _, _, _), step(Id, T)]>>true, Actions, Steps).

%!  instance_sources(+Instance, -Sources) is det.
%
%   Where each action of a plan instance finds the objects it needs on the
%   table: Sources is a list Id-[Object-Label, ...] of the part_location/2
%   preconditions of its actions (pickup: the object taken; assemble: the
%   object mated onto), Label the position's label in the instance (tr5 or
%   a stable pose). Phase 2 needs it when an object has several initial
%   positions (a stock of identical parts): it says which part is taken.

instance_sources(instance(Actions, _), Sources) :-
    convlist(action_sources, Actions, Sources).

action_sources(action(Id, _, preconditions(Ops, _), _, _), Id-Pairs) :-
    findall(O-L, member(op(_, _, part_location(O, L)), Ops), Pairs),
    Pairs \== [].

%!  check_instance(+Problem, +Steps, +Sources, +Bound, -Augmented) is semidet.
%
%   Steps of the loaded problem Problem is a list of step(Id, Action) in execution order. Augmented is
%   aug(Steps1, ErrorCount, Verifications, Recoveries, Verdicts, Geometry):
%   Steps1 with sensing and squeezes inserted; Verdicts a list of
%   verdict(Id, Action, Dicts) (Python's verdict dicts: constraint, bound,
%   threshold, satisfied, ...); Geometry a list of Id-Dict (tool pose, joint
%   angles, placement). Fails if the instance cannot be executed at all (a
%   geometric precondition fails: no placement, no joint solution).
%   It fails as soon as the instance has Bound errors (it cannot beat the
%   best so far; inf for no bound); Sources as instance_sources/2 gives
%   them ([]: every object has one initial position).

check_instance(Problem, Steps, Sources, Bound, aug(Final, Errors, Verifs, Recovs, Verdicts, Geometry)) :-
    must_be(atom, Problem),
    must_be(list, Steps),
    must_be(list, Sources),
    sources_dict(Sources, From0),
    From = ctx(Problem, From0),
    remedy_loop(From, Steps, [], Bound, Final, Failed, Verdicts, Geometry),
    length(Failed, Errors),
    maplist(failed_step(Final), Failed, FailedSteps),
    maplist(verification, FailedSteps, Verifs),
    maplist(recovery, FailedSteps, Recovs).

failed_step(Steps, Id, step(Id, A)) :-
    memberchk(step(Id, A), Steps).

%   remedy_loop(+From, +Steps, +GivenUp, +Bound, -Final, -Failed,
%   -Verdicts, -Geometry): run the steps; at the first failing action not
%   yet given up, try the remedies in order; an action no remedy helps is
%   given up (it counts as an error) and the run goes on past it. From is
%   ctx(Problem, Sources), Sources the instance's sources as sources_dict/2
%   gives them.

remedy_loop(From, Steps, GivenUp, Bound, Final, Failed, Verdicts, Geometry) :-
    run(From, Steps, GivenUp, Result),
    (   Result = ok(Verdicts, Geometry)
    ->  Final = Steps, reverse(GivenUp, Failed)
    ;   Result = failed(Step, Before)
    ->  (   remedy(From, Step, Before, Steps, GivenUp, Steps1)
        ->  remedy_loop(From, Steps1, GivenUp, Bound, Final, Failed, Verdicts, Geometry)
        ;   Step = step(Id, _),
            length(GivenUp, N0),
            N is N0 + 1,
            (Bound == inf -> true ; N < Bound),
            remedy_loop(From, Steps, [Id|GivenUp], Bound, Final, Failed, Verdicts, Geometry)
        )
    ).

%   run(+From, +Steps, +GivenUp, -Result): propagate the world through
%   Steps (From: see sources_dict/2).
%   Result = ok(Verdicts, Geometry); failed(Step, Prefix) for the first
%   action whose uncertainty-reduction preconditions are not all satisfied
%   and that is not in GivenUp; infeasible(Step) if a geometric
%   precondition fails (the run cannot go on; the caller fails).

run(ctx(Problem, From), Steps, GivenUp, Result) :-
    maplist(step_dict, Steps, Dicts),
    py_bridge(ur_world(Problem, Dicts, From), W0),
    run(Steps, GivenUp, W0, [], [], [], Result0),
    Result0 \= infeasible(_),
    Result = Result0.

run([], _, _, _, Vs0, Gs0, ok(Vs, Gs)) :-
    reverse(Vs0, Vs),
    reverse(Gs0, Gs).
run([Step|Rest], GivenUp, W0, Prefix, Vs0, Gs0, Result) :-
    Step = step(Id, Action),
    step_dict(Step, Dict),
    py_bridge(ur_step(W0, Dict), -(Checks, W1, Geo)),
    (   Checks == []
    ->  Vs1 = Vs0
    ;   Vs1 = [verdict(Id, Action, Checks)|Vs0]
    ),
    (   member(C, Checks), get_dict(kind, C, geometric), \+ satisfied(C)
    ->  Result = infeasible(Step)
    ;   \+ all_satisfied(Checks), \+ memberchk(Id, GivenUp)
    ->  reverse(Prefix, Before), Result = failed(Step, Before)
    ;   step_id_text(Id, IdText),
        run(Rest, GivenUp, W1, [Step|Prefix], Vs1, [IdText-Geo|Gs0], Result)
    ).

all_satisfied(Checks) :-
    forall(member(C, Checks), satisfied(C)).

%   janus passes Python's True as @(true).
satisfied(C) :-
    get_dict(satisfied, C, S),
    S == @(true).

%   remedy(+From, +Failing, +Before, +Steps, +GivenUp, -Steps1): the first
%   remedy of Sec. 4.3 that makes Failing's preconditions hold.

remedy(From, step(Id, pickup(Obj, _)), _, Steps, GivenUp, Steps1) :-
    \+ inserted_for(Id, Steps),
    insert_before(Id, [step(sense(Id, 1), dense_range_scan(Obj))], Steps, Steps1),
    passes(From, Id, Steps1, GivenUp).
remedy(From, step(Id, assemble(O1, O2, _, _, _)), Before, Steps, GivenUp, Steps1) :-
    \+ inserted_for(Id, Steps),
    establisher_of_holding(O1, Before, EId),
    Scans = [ step(sense(Id, 1), dense_range_scan(O1)),
              step(sense(Id, 2), dense_range_scan(O2)) ],
    (   insert_before(EId, Scans, Steps, Steps1),
        passes(From, Id, Steps1, GivenUp)
    ->  true
    ;   append(Scans, [step(squeeze(Id), squeeze(O2))], WithSqueeze),
        insert_before(EId, WithSqueeze, Steps, Steps1),
        passes(From, Id, Steps1, GivenUp)
    ).

inserted_for(Id, Steps) :-
    (   memberchk(step(sense(Id, _), _), Steps)
    ;   memberchk(step(squeeze(Id), _), Steps)
    ),
    !.

%   The last pickup of O1 before the assemble establishes holding(O1, _).
establisher_of_holding(O1, Before, EId) :-
    reverse(Before, Rev),
    member(step(EId, pickup(O1, _)), Rev),
    !.

insert_before(Id, New, Steps, Steps1) :-
    append(Pre, [step(Id, A)|Post], Steps),
    !,
    append(Pre, New, Pre1),
    append(Pre1, [step(Id, A)|Post], Steps1).

%   passes(+From, +Id, +Steps, +GivenUp): with Steps, action Id's
%   preconditions hold (the run gets past Id).
passes(From, Id, Steps, GivenUp) :-
    run(From, Steps, GivenUp, Result),
    (   Result = ok(_, _)
    ->  true
    ;   Result = failed(_, Before),
        memberchk(step(Id, _), Before)
    ).

%!  step_dict(+Step, -Dict) is det.
%
%   The data Python receives for a step: id (text), name, atomic arguments
%   (compound arguments as quoted text).

step_dict(step(Id, Action), _{id: IdText, name: Name, args: Args}) :-
    step_id_text(Id, IdText),
    Action =.. [Name|Args0],
    maplist(arg_data, Args0, Args).

%   sources_dict(+Sources, -From): the list Id-[Obj-Label, ...] of
%   instance_sources/2 as the dict _{Id: _{Obj: Label}} Python's
%   new_world/3 reads; made once per instance, passed to every run.

sources_dict(Sources, From) :-
    maplist([Id-Pairs, IdText-D]>>( step_id_text(Id, IdText),
                                     dict_pairs(D, _, Pairs) ),
            Sources, KVs),
    dict_pairs(From, _, KVs).

%!  step_id_text(+Id, -Text) is det.
%
%   Inserted steps get ids naming the action they serve: sense_action_2_1,
%   squeeze_action_1.

step_id_text(sense(Id, K), T) :- !, format(atom(T), 'sense_~w_~w', [Id, K]).
step_id_text(squeeze(Id), T) :- !, format(atom(T), 'squeeze_~w', [Id]).
step_id_text(Id, Id).

arg_data(A, A) :- atomic(A), !.
arg_data(T, S) :- format(string(S), '~q', [T]).

%   verification(+Step, -V) and recovery(+Step, -R): Figs. 12-13 from the
%   templates in kb/templates/sensing.pl, their action id bound.
verification(step(Id, Action), V) :-
    (   spar_sensing:verification_template(Action, V0)
    ->  V0 = verification(Id, _, _), V = V0
    ;   existence_error(verification_template, Action)
    ).
recovery(step(Id, Action), R) :-
    (   spar_sensing:recovery_template(Action, R0)
    ->  R0 = recovery(Id, _), R = R0
    ;   existence_error(recovery_template, Action)
    ).

%!  ur_dict(+Result, -Dict) is det.
%
%   The phase-2 Result (phase2/4) as a dict for janus, the "instance" of the
%   JSON schema (docs/json-schema.md): bindings, steps (each with its kind,
%   the action it serves, tool pose, joint angles, placement), constraints
%   (one per checked uncertainty-reduction inequality: action, constraint,
%   bound, threshold, satisfied), verifications, recoveries, error_count,
%   instances_examined, instance_cap, complete. For no_instance/3 the dict
%   has steps = [] and error_count = null.

ur_dict(ur(aug(Steps, E, Vs, Rs, Verdicts, Geo, Bindings), N, Cap, Complete), D) :-
    !,
    maplist(binding_pair, Bindings, BPairs),
    dict_pairs(BDict, _, BPairs),
    maplist(step_out(Geo), Steps, SDicts),
    foldl(verdict_dicts, Verdicts, [], Cs0),
    reverse(Cs0, Cs),
    maplist(term_dict, Vs, VDicts),
    maplist(term_dict, Rs, RDicts),
    json_bool(Complete, C),
    D = _{bindings: BDict, steps: SDicts, constraints: Cs, verifications: VDicts,
          recoveries: RDicts, error_count: E, instances_examined: N,
          instance_cap: Cap, complete: C}.
ur_dict(no_instance(N, Cap, Complete), D) :-
    json_bool(Complete, C),
    D = _{bindings: _{}, steps: [], constraints: [], verifications: [], recoveries: [],
          error_count: @(none), instances_examined: N, instance_cap: Cap, complete: C,
          reason: "no instance could be executed: a put-down without a reachable placement or a step without a joint solution"}.

json_bool(true, @(true)) :- !.
json_bool(_, @(false)).

binding_pair(V = L, V-L).

step_out(Geo, step(Id, Action), D) :-
    step_id_text(Id, IdText),
    step_kind(Id, Action, Kind, Serves),
    format(string(Term), "~q", [Action]),
    Action =.. [Name, Obj|_],
    (   memberchk(IdText-G, Geo) -> true ; G = _{} ),
    geo_value(G, tool_pose, TP),
    geo_value(G, joints_deg, Q),
    geo_value(G, placement, Pl),
    geo_value(G, ik_solutions_deg, Sols),
    geo_value(G, from, From),
    D = _{id: IdText, kind: Kind, serves: Serves, term: Term, name: Name, object: Obj,
          tool_pose: TP, joints_deg: Q, ik_solutions_deg: Sols, placement: Pl,
          from: From}.

step_kind(sense(A, _), _, sensing, A) :- !.
step_kind(squeeze(A), _, squeeze, A) :- !.
step_kind(Id, _, manipulation, Id).

geo_value(G, K, V) :-
    (   get_dict(K, G, V0), V0 \== 'None' -> V = V0 ; V = @(none) ).

verdict_dicts(verdict(_, _, Checks), Acc0, Acc) :-
    foldl([C, A0, [C|A0]]>>true, Checks, Acc0, Acc).

term_dict(T, _{action: Id, term: S}) :-
    arg(1, T, Id),
    format(string(S), "~q", [T]).

%!  print_ur(+Result) is det.
%
%   Print the chosen plan instance: its steps in order (inserted sensing and
%   squeezes marked), the verdict of every uncertainty-reduction constraint
%   (bound against threshold), verifications, recoveries, the error count.

print_ur(no_instance(N, Cap, _)) :-
    !,
    format("PHASE 2: no executable plan instance among ~w examined (cap ~w)~n", [N, Cap]).
print_ur(ur(aug(Steps, E, Vs, Rs, Verdicts, Geo, Bindings), N, Cap, Complete)) :-
    (   Complete == true -> All = ", all instances" ; All = "" ),
    format("PLAN INSTANCE (~w examined, cap ~w~s), error count ~w~n", [N, Cap, All, E]),
    format("  bindings: ~q~n", [Bindings]),
    forall(nth1(I, Steps, step(Id, A)), print_step(Geo, I, Id, A)),
    format("UNCERTAINTY-REDUCTION CONSTRAINTS~n"),
    forall(member(verdict(Id, _, Cs), Verdicts),
           forall(member(C, Cs), print_verdict(Id, C))),
    (   Vs == [] -> true
    ;   format("VERIFICATIONS~n"), forall(member(V, Vs), format("  ~q~n", [V]))
    ),
    (   Rs == [] -> true
    ;   format("RECOVERIES~n"), forall(member(R, Rs), format("  ~q~n", [R]))
    ).

print_step(Geo, I, Id, A) :-
    step_id_text(Id, T),
    step_kind(Id, A, Kind, _),
    (   Kind == manipulation -> Mark = "" ; format(string(Mark), "  [~w]", [Kind]) ),
    format("  ~w. ~w: ~q~s~n", [I, T, A, Mark]),
    (   memberchk(T-G, Geo), get_dict(joints_deg, G, Q), is_list(Q)
    ->  format("       joints (deg): ~w~n", [Q])
    ;   true
    ),
    (   memberchk(T-G2, Geo), get_dict(placement, G2, P), is_dict(P)
    ->  format("       placement: x=~w y=~w z=~w yaw=~w deg (~w)~n",
               [P.x, P.y, P.z, P.yaw_deg, P.pose])
    ;   true
    ).

print_verdict(Id, C) :-
    (   satisfied(C) -> V = "satisfied" ; V = "NOT satisfied" ),
    (   get_dict(kind, C, geometric)
    ->  format("  ~w ~w: ~w (~w)~n", [Id, C.constraint, V, C.description])
    ;   format("  ~w ~w: bound ~4f ~w ~w: ~w~n",
               [Id, C.constraint, C.bound, C.sense, C.threshold, V])
    ).
