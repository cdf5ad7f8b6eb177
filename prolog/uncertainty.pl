/*  spar-py: phase 2, uncertainty-reduction planning (Secs. 2, 3.3, 4.3).

    Plan instances (a solution of the constraint network x a linearisation of
    the ordering graph) are generated lazily from the phase-1 partial plan.
    Each is run with the world's uncertainty propagated forward by Python
    (numbers and symbols, reached through foreign.pl): ONE call,
    spar_py.planning.engine:evaluate/5, per run of an instance, which executes the
    whole step list and returns plain data: each step's verdicts, where the
    run stopped (ok, failed at a step, infeasible at a step) and, for a run
    that went through, a token naming its geometry (tool poses, joints, the
    poses of every part), which stays in Python and is joined to the plan's
    JSON there. Every decision
    stays here. At the first action whose uncertainty-reduction
    preconditions fail (and that is not given up), the remedies are read as
    data from kb/templates/spar_sensing.pl and tried in order:

      1. spar_sensing:remedy_rule/3, clause by clause: insert its actions
         (dense_range_scan sensing, squeeze) before the failing action or
         before the action that established one of its preconditions
         (Sec. 4.3: a scan before a pickup; two scans, then two scans and a
         squeeze, before the pickup that establishes holding for an
         assemble), keeping the first that makes the action's
         preconditions hold;
      2. otherwise the action is given up: the error count + 1, a
         verification action (Fig. 12) and a local recovery plan (Fig. 13)
         for it, and the run goes on past it.

    What a sensing action leaves (the bounds of the uncertainty variables it
    introduces) is read from spar_sensing:sensing_rule/5 (Fig. 11, in the
    units of spar_sensing:sensing_units/2) and passed to Python with every
    evaluation; a problem file's sensors entry takes precedence there.

    The first instance with no error wins; otherwise the one with the fewest
    errors among at most max_instances(Cap) examined. Each next instance is
    searched knowing the earlier ones (partial_plan:next_instance/3): a run
    that stops at a step it cannot execute says on what that depends
    (Python's phase2.nogood), and no later instance meets it again.
*/
:- module(uncertainty,
          [ phase2/4,              % +Problem, +Partial, +Options, -Result
            check_instance/5,      % +Problem, +Steps, +Sources, +Bound, -Augmented
            instance_steps/3,      % +Instance, -Steps, -Bindings
            instance_sources/2,    % +Instance, -Sources
            ur_dict/2,             % +Result, -Dict
            step_id_text/2,        % +Id, -Text
            print_ur/1             % +Result
          ]).
:- use_module(library(apply)).
:- use_module(library(lists)).
:- use_module(library(option)).
:- use_module(library(error)).
:- use_module(library(yall)).
:- use_module(library(aggregate), [aggregate_all/3]).
:- use_module(foreign, [py_bridge/2, term_data/2]).
:- use_module(spar_defaults, [default_option/2]).
:- use_module(partial_plan, [instance_search/1, next_instance/3, search_examined/3, search_nogood/3,
                              instance_nogood/4, partial_ordering/2, path_before/3]).
:- use_module(spar_paths, []).    % the file search path spar
:- use_module(spar(kb/templates/spar_sensing), []).
:- use_module(spar(kb/templates/spar_actions), []).

%!  phase2(+Problem, +Partial, +Options, -Result) is det.
%
%   Phase 2 of the loaded problem Problem on its phase-1 plan Partial.
%   Result = ur(Best, Examined, Cap, Complete), or no_instance(Examined, Cap,
%   Complete) when no instance could be executed at all (every one needed
%   a put-down with no reachable placement). Best is an augmented instance
%   aug(Steps, ErrorCount, Verifications, Recoveries, Verdicts, Geometry,
%   Bindings) (see check_instance/5); Examined the instances checked;
%   Complete true if the partial plan has no further instance.
%   Options: max_instances(Cap) (default: spar_defaults:default_option/2).

phase2(Problem, Partial, Options, Result) :-
    must_be(atom, Problem),
    default_option(max_instances, Cap0),
    option(max_instances(Cap), Options, Cap0),
    must_be(positive_integer, Cap),
    instance_search(Search),
    search_loop(Problem, Partial, Cap, Search, best(none, inf, 0), 0, Result).

%   search_loop(+Problem, +Partial, +Cap, +Search, +Best, +N, -Result):
%   examine the next instance (partial_plan:next_instance/3) until one has
%   no error, or only errors every instance has (forced/3), Cap are
%   examined or none is left; N examined so far, Best best(Aug, Errors,
%   Forced) the best of them (best(none, inf, 0) before any), Search what
%   the search knows (the instances examined, the nogoods learnt).
search_loop(Problem, Partial, Cap, Search0, Best0, N0, Result) :-
    (   N0 >= Cap
    ->  search_result(Best0, N0, Cap, false, Result)
    ;   next_instance(Partial, Search0, Instance)
    ->  N is N0 + 1,
        examine(Problem, Partial, Instance, Best0, Best, Search0, Search),
        (   Best = best(_, E, F), (E == 0 ; E == F)
        ->  search_result(Best, N, Cap, false, Result)
        ;   search_loop(Problem, Partial, Cap, Search, Best, N, Result)
        )
    ;   search_result(Best0, N0, Cap, true, Result)
    ).

search_result(best(none, _, _), N, Cap, Complete, no_instance(N, Cap, Complete)) :- !.
search_result(best(Aug, _, _), N, Cap, Complete, ur(Aug, N, Cap, Complete)).

%   examine(+Problem, +Partial, +Instance, +Best0, -Best, +Search0, -Search):
%   run Instance (check_instance/6, bounded by Best0's error count); Best
%   the better of Best0 and it, Search0 with it examined and with the
%   nogood of each run that stopped at a step it could not execute.
examine(Problem, Partial, Instance, best(Aug0, E0, F0), Best, Search0, Search) :-
    instance_steps(Instance, Steps, Bindings),
    instance_sources(Instance, Sources),
    Learnt = learnt([]),
    (   check_instance(Problem, Steps, Sources, E0, Learnt, aug(S, E, V, R, C, G)),
        (E0 == inf ; E < E0)
    ->  arg(1, Learnt, Ls0),
        forced(Partial, Ls0, F),
        Best = best(aug(S, E, V, R, C, G, Bindings), E, F)
    ;   Best = best(Aug0, E0, F0)
    ),
    arg(1, Learnt, Ls1),
    exclude([X]>>(X = hopeless(_, _)), Ls1, Ls),
    search_examined(Instance, Search0, Search1),
    foldl(learn(Partial, Instance), Ls, Search1, Search).

%   forced(+Partial, +Learnt, -F): how many of the steps an instance gave up
%   as beyond every remedy (hopeless(Id, Parts) in Learnt: the clearance of
%   the mates of Parts breaks its insertion check whatever the grasps,
%   positions and remedies) every instance of Partial gives up too: those
%   whose Parts are each inserted necessarily before Id (or never: the base),
%   so that in every linearisation they are mated the same way when Id
%   comes, and the check meets the same floor. No instance has fewer errors
%   than F.
forced(Partial, Learnt, F) :-
    partial_ordering(Partial, PriorTos),
    Partial = partial(Actions, _, _, _),
    aggregate_all(count,
                  ( member(hopeless(Id, Parts), Learnt),
                    forall(member(P, Parts), inserted_before(P, Id, Actions, PriorTos)) ),
                  F).

inserted_before(Part, Id, Actions, PriorTos) :-
    (   memberchk(action(B, assemble(Part, _, _, _, _), _, _, _), Actions),
        B \== Id
    ->  path_before(B, Id, PriorTos)
    ;   true
    ).

learn(Partial, Instance, L, Search0, Search) :-
    (   instance_nogood(Partial, Instance, L, Ng)
    ->  search_nogood(Ng, Search0, Search)
    ;   Search = Search0
    ).

%!  instance_steps(+Instance, -Steps, -Bindings) is det.
%
%   The steps step(Id, Action) of a plan instance (partial_plan:partial_instances/2)
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
%   Steps of the loaded problem Problem is a list of step(Id, Action) in
%   execution order. Augmented is aug(Steps1, ErrorCount, Verifications,
%   Recoveries, Verdicts, Geometry): Steps1 with sensing and squeezes
%   inserted; Verdicts a list of verdict(Id, Action, Dicts) (Python's
%   verdict dicts: constraint, bound, threshold, sense, satisfied, ...);
%   Geometry geo(Problem, Token): Token names the run's geometry (tool
%   poses, joint angles, IK solutions, placements, poses, held parts and
%   the instance's motions), which stays in Python (spar_py.planning.run)
%   and is joined to the plan there. Fails if the instance cannot be executed
%   at all (a geometric precondition fails: no placement, no joint
%   solution). It fails as soon as the instance has Bound errors (it cannot
%   beat the best so far; inf for no bound); Sources as instance_sources/2
%   gives them ([]: every object has one initial position).
%
%   @error domain_error(sensing_error_transform, E) if a sensing rule's
%   error transformation is not the trans(Dx, Dy, Dz) rotz(Theta) Python
%   implements.

check_instance(Problem, Steps, Sources, Bound, Augmented) :-
    check_instance(Problem, Steps, Sources, Bound, none, Augmented).

%   check_instance(+Problem, +Steps, +Sources, +Bound, +Learnt, -Augmented):
%   as check_instance/5; a run that stops at a step it cannot execute and
%   whose nogood Python can state (phase2.nogood: on what any instance
%   stopping there depends) adds learnt(Step, LabelIds, Prefix, Pairs) to
%   Learnt (learnt(List), nb_setarg/3; none: not kept), which phase2/4
%   turns into the search's nogood (partial_plan:instance_nogood/4).

check_instance(Problem, Steps, Sources, Bound, Learnt,
               aug(Final, Errors, Verifs, Recovs, Verdicts, Geometry)) :-
    must_be(atom, Problem),
    must_be(list, Steps),
    must_be(list, Sources),
    sources_dict(Sources, From),
    sensing_data(Sensing),
    Ctx = ctx(Problem, From, Sensing, Learnt),
    run(Ctx, Steps, [], Result),
    remedy_loop(Ctx, Steps, [], Result, Bound, Final, Failed, Verdicts, Geometry),
    length(Failed, Errors),
    maplist(failed_step(Final), Failed, FailedSteps),
    maplist(verification, FailedSteps, Verifs),
    maplist(recovery, FailedSteps, Recovs).

failed_step(Steps, Id, step(Id, A)) :-
    memberchk(step(Id, A), Steps).

%   remedy_loop(+Ctx, +Steps, +GivenUp, +Result, +Bound, -Final, -Failed,
%   -Verdicts, -Geometry): Result is the run of Steps (run/4). At its first
%   failing action not yet given up, try the remedies in order; an action
%   no remedy helps is given up (it counts as an error) and the run goes on
%   past it. An action whose unmet checks no remedy can reach (Python's
%   hopeless: the clearance its mates leave alone breaks them, see
%   phase2/steps.py's _floors) is given up without trying them. Ctx is ctx(Problem, Sources, Sensing, Learnt) (sources_dict/2,
%   sensing_data/1).

remedy_loop(_, Steps, GivenUp, ok(Verdicts, Geometry), _, Steps, Failed, Verdicts, Geometry) :-
    !,
    reverse(GivenUp, Failed).
remedy_loop(Ctx, Steps, GivenUp, failed(Step, Before, Hopeless), Bound, Final, Failed, Verdicts, Geometry) :-
    (   Hopeless == false,
        remedy(Ctx, Step, Before, Steps, GivenUp, Steps1, Result1)
    ->  remedy_loop(Ctx, Steps1, GivenUp, Result1, Bound, Final, Failed, Verdicts, Geometry)
    ;   Step = step(Id, _),
        keep_hopeless(Ctx, Id, Hopeless),
        length(GivenUp, N0),
        N is N0 + 1,
        (Bound == inf -> true ; N < Bound),
        GivenUp1 = [Id|GivenUp],
        run(Ctx, Steps, GivenUp1, Result1),
        remedy_loop(Ctx, Steps, GivenUp1, Result1, Bound, Final, Failed, Verdicts, Geometry)
    ).

%   run(+Ctx, +Steps, +GivenUp, -Result): run Steps in one Python call
%   (spar_py.planning.engine:evaluate/5). Result = ok(Verdicts, Geometry), or
%   failed(Step, Before, Hopeless) for the first action whose
%   uncertainty-reduction preconditions are not all satisfied and that is
%   not in GivenUp, Before the steps before it, Hopeless true when no remedy
%   can make them hold. Fails if a geometric precondition fails (the
%   instance cannot be executed).

run(ctx(Problem, From, Sensing, Learnt), Steps, GivenUp, Result) :-
    maplist(step_dict, Steps, Dicts),
    maplist(step_id_text, GivenUp, GivenUpText),
    py_bridge(evaluate(Problem, Dicts, From, GivenUpText, Sensing), Eval),
    keep_nogood(Learnt, Eval),
    atom_string(Status, Eval.status),
    eval_result(Status, Problem, Eval, Steps, Result).

%   keep_nogood(+Learnt, +Eval): add the run's nogood (Python's
%   phase2.nogood: step, labels, prefix, before, ids as strings) to Learnt
%   as learnt(Step, LabelIds, Prefix, Pairs); nothing without one or
%   without a store.
keep_nogood(Learnt, Eval) :-
    (   Learnt = learnt(List0),
        get_dict(nogood, Eval, NG),
        is_dict(NG)
    ->  atom_string(Step, NG.step),
        maplist(text_atom, NG.labels, Ids),
        maplist(text_atom, NG.prefix, Prefix),
        maplist(text_pair, NG.before, Pairs),
        nb_setarg(1, Learnt, [learnt(Step, Ids, Prefix, Pairs)|List0])
    ;   true
    ).

%   keep_hopeless(+Ctx, +Id, +Hopeless): a step given up as beyond every
%   remedy, with the parts its failure depends on, kept in the run's store
%   as hopeless(Id, Parts) for forced/3; nothing otherwise.
keep_hopeless(ctx(_, _, _, Learnt), Id, Hopeless) :-
    (   Hopeless = hopeless(Parts), is_list(Parts), Learnt = learnt(List0)
    ->  nb_setarg(1, Learnt, [hopeless(Id, Parts)|List0])
    ;   true
    ).

text_atom(S, A) :-
    atom_string(A, S).

text_pair([S1, S2], A1-A2) :-
    atom_string(A1, S1),
    atom_string(A2, S2).

%   eval_result(+Status, +Problem, +Eval, +Steps, -Result): Eval holds each
%   step's id and verdicts; a run that went through also its token (the
%   geometry Python keeps).
eval_result(ok, Problem, Eval, Steps, ok(Verdicts, geo(Problem, Token))) :-
    foldl(step_record, Eval.steps, Steps, Verdicts0, []),
    exclude([verdict(_, _, [])]>>true, Verdicts0, Verdicts),
    get_dict(token, Eval, Token).

eval_result(failed, _, Eval, Steps, failed(Step, Before, Hopeless)) :-
    (   get_dict(hopeless, Eval, @(true))
    ->  (   get_dict(depends, Eval, Ds)
        ->  maplist(text_atom, Ds, Parts), Hopeless = hopeless(Parts)
        ;   Hopeless = hopeless(unknown)
        )
    ;   Hopeless = false
    ),
    atom_string(At, Eval.at),
    append(Before, [Step|_], Steps),
    Step = step(Id, _),
    step_id_text(Id, At),
    !.

step_record(Record, step(Id, Action), [verdict(Id, Action, Record.verdicts)|Vs], Vs).

%   janus passes Python's True as @(true).
satisfied(C) :-
    get_dict(satisfied, C, S),
    S == @(true).

%   remedy(+Ctx, +Failing, +Before, +Steps, +GivenUp, -Steps1, -Result):
%   the first remedy rule (spar_sensing:remedy_rule/3) whose insertion
%   makes Failing's preconditions hold; Result the run of Steps1. A remedy
%   is tried once per action: not when something is inserted for it
%   already.

remedy(Ctx, step(Id, Action), Before, Steps, GivenUp, Steps1, Result) :-
    \+ inserted_for(Id, Steps),
    spar_sensing:remedy_rule(Action, Where, Inserted),
    insertion_point(Where, Id, Before, At),
    inserted_steps(Inserted, Id, New),
    insert_before(At, New, Steps, Steps1),
    run(Ctx, Steps1, GivenUp, Result),
    gets_past(Id, Result),
    !.

inserted_for(Id, Steps) :-
    (   memberchk(step(sense(Id, _), _), Steps)
    ;   memberchk(step(squeeze(Id), _), Steps)
    ),
    !.

%   insertion_point(+Where, +Id, +Before, -At): the id of the step the
%   remedy goes before (remedy_rule/3's Where).
insertion_point(action, Id, _, Id).
insertion_point(establisher(Condition), _, Before, At) :-
    reverse(Before, Rev),
    member(step(At, A), Rev),
    establishes(A, Condition),
    !.

%   establishes(+Action, ?Condition): Condition is in the add list of
%   Action's template (Figs. 2-4); sensing and squeezes establish nothing.
establishes(Action, Condition) :-
    phrase(spar_actions:action_template(Action, action(_, _, _, addlist(Adds), _)), [], _),
    member(C, Adds),
    subsumes_term(Condition, C),
    !.

%   inserted_steps(+Actions, +Id, -Steps): the actions a remedy inserts
%   for action Id as steps: sensing actions get ids sense(Id, K) (K = 1,
%   2, ... among them), a squeeze squeeze(Id).
inserted_steps(Actions, Id, Steps) :-
    foldl(inserted_step(Id), Actions, Steps, 1, _).

inserted_step(Id, A, step(sense(Id, K), A), K, K1) :-
    sensing_action(A),
    !,
    K1 is K + 1.
inserted_step(Id, squeeze(O), step(squeeze(Id), squeeze(O)), K, K) :- !.
inserted_step(_, A, _, _, _) :-
    domain_error(remedy_action, A).

sensing_action(A) :-
    \+ \+ spar_sensing:sensing_rule(A, _, _, _, _).

insert_before(Id, New, Steps, Steps1) :-
    append(Pre, [step(Id, A)|Post], Steps),
    !,
    append(Pre, New, Pre1),
    append(Pre1, [step(Id, A)|Post], Steps1).

%   gets_past(+Id, +Result): in the run Result, action Id's
%   preconditions hold (it is done, or the run fails at a later step).
gets_past(_, ok(_, _)) :- !.
gets_past(Id, failed(_, Before, _)) :-
    memberchk(step(Id, _), Before).

%!  step_dict(+Step, -Dict) is det.
%
%   The data Python receives for a step: id (text), name, arguments as
%   term data (foreign:term_data/2).

step_dict(step(Id, Action), _{id: IdText, name: Name, args: Args}) :-
    step_id_text(Id, IdText),
    Action =.. [Name|Args0],
    maplist(term_data, Args0, Args).

%   sources_dict(+Sources, -From): the list Id-[Obj-Label, ...] of
%   instance_sources/2 as the dict _{Id: _{Obj: Label}} Python's
%   new_world/4 reads; made once per instance, passed to every run.

sources_dict(Sources, From) :-
    maplist([Id-Pairs, IdText-D]>>( step_id_text(Id, IdText),
                                     dict_pairs(D, _, Pairs) ),
            Sources, KVs),
    dict_pairs(From, _, KVs).

%!  sensing_data(-Data:dict) is det.
%
%   What each sensing action leaves, from spar_sensing:sensing_rule/5, as
%   the data Python's phase2.sensing_bounds/2 reads: Name: _{dx: [Lo, Hi],
%   dy: .., dz: .., dtheta: .., units: _{length: L, angle: A}}, the
%   variables named by their place in the rule's error transformation
%   tm([[cos(T), sin(T), 0], [-1*sin(T), cos(T), 0], [0, 0, 1], [Dx, Dy, Dz]])
%   and bounded by its supinf_less/2 terms, in spar_sensing:sensing_units/2.
%
%   @error domain_error(sensing_error_transform, E) for another shape.

sensing_data(Data) :-
    spar_sensing:sensing_units(L, A),
    findall(Name-D,
            ( spar_sensing:sensing_rule(S, Vars, Bounds, ErrTm, _),
              functor(S, Name, _),
              rule_bounds(ErrTm, Vars, Bounds, D0),
              put_dict(units, D0, _{length: L, angle: A}, D)
            ),
            Pairs),
    dict_pairs(Data, _, Pairs).

rule_bounds(ErrTm, Vars, Bounds, _{dx: X, dy: Y, dz: Z, dtheta: T}) :-
    (   subsumes_term(tm([[cos(Th), sin(Th), 0], [-1*sin(Th), cos(Th), 0], [0, 0, 1], [_, _, _]]), ErrTm),
        ErrTm = tm([[cos(Th), _, _], _, _, [Dx, Dy, Dz]]),
        Vs = [Dx, Dy, Dz, Th],
        maplist(var, Vs),
        forall(member(V, Vs), (member(supinf_variable(W), Vars), W == V))
    ->  maplist(var_interval(Bounds), Vs, [X, Y, Z, T])
    ;   domain_error(sensing_error_transform, ErrTm)
    ).

var_interval(Bounds, V, [Lo, Hi]) :-
    (   member(supinf_less(Lo, W1), Bounds), W1 == V, number(Lo),
        member(supinf_less(W2, Hi), Bounds), W2 == V, number(Hi)
    ->  true
    ;   existence_error(supinf_bounds, V)
    ).

%!  step_id_text(+Id, -Text) is det.
%
%   Inserted steps get ids naming the action they serve: sense_action_2_1,
%   squeeze_action_1.

%!  step_id_text(+Id, -Text:atom) is det.
%
%   The id of a plan-instance step as the JSON and the planning run name
%   it: Id for an action, sense_<action>_<k> and squeeze_<action> for the
%   steps a remedy inserted.

step_id_text(sense(Id, K), T) :- !, format(atom(T), 'sense_~w_~w', [Id, K]).
step_id_text(squeeze(Id), T) :- !, format(atom(T), 'squeeze_~w', [Id]).
step_id_text(Id, Id).


%   verification(+Step, -V) and recovery(+Step, -R): Figs. 12-13 from the
%   templates in kb/templates/spar_sensing.pl, their action id bound.
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
%   the action it serves, its term as text and its args as term data; their
%   tool poses, joint angles, placements, part poses and held parts are
%   joined in Python by the instance's token), constraints (one per checked precondition: action,
%   constraint, bound, threshold, sense, satisfied), verifications and
%   recoveries (the term as text and as data), error_count,
%   instances_examined, instance_cap, complete. For no_instance/3 the dict
%   has steps = [] and error_count = null.

ur_dict(ur(aug(Steps, E, Vs, Rs, Verdicts, Geo, Bindings), N, Cap, Complete), D) :-
    !,
    maplist(binding_pair, Bindings, BPairs),
    dict_pairs(BDict, _, BPairs),
    maplist(step_out, Steps, SDicts),
    foldl(verdict_dicts, Verdicts, [], Cs0),
    reverse(Cs0, Cs),
    maplist(term_dict, Vs, VDicts),
    maplist(term_dict, Rs, RDicts),
    json_bool(Complete, C),
    Geo = geo(_, Token),
    D = _{bindings: BDict, steps: SDicts, constraints: Cs, verifications: VDicts,
          recoveries: RDicts, error_count: E, instances_examined: N,
          instance_cap: Cap, complete: C, token: Token}.
ur_dict(no_instance(N, Cap, Complete), D) :-
    json_bool(Complete, C),
    D = _{bindings: _{}, steps: [], constraints: [], verifications: [], recoveries: [],
          error_count: @(none), instances_examined: N, instance_cap: Cap, complete: C,
          motion: @(none), reason: "no instance could be executed: a put-down without a reachable placement or a step without a joint solution"}.

json_bool(true, @(true)) :- !.
json_bool(_, @(false)).

binding_pair(V = L, V-L).

%   step_out(+Step, -Dict): the step as the plan shows it: its id, kind,
%   the action it serves, its term as text and as data. Its geometry stays
%   in Python and is joined there by the instance's token.
step_out(step(Id, Action), D) :-
    step_id_text(Id, IdText),
    step_kind(Id, Action, Kind, Serves),
    format(string(Term), "~q", [Action]),
    Action =.. [Name, Obj|Args0],
    maplist(term_data, [Obj|Args0], Args),
    D = _{id: IdText, kind: Kind, serves: Serves, term: Term, name: Name, object: Obj,
          args: Args}.

step_kind(sense(A, _), _, sensing, A) :- !.
step_kind(squeeze(A), _, squeeze, A) :- !.
step_kind(Id, _, manipulation, Id).

verdict_dicts(verdict(_, _, Checks), Acc0, Acc) :-
    foldl([C, A0, [C|A0]]>>true, Checks, Acc0, Acc).

term_dict(T, _{action: Id, term: S, data: D}) :-
    arg(1, T, Id),
    format(string(S), "~q", [T]),
    term_data(T, D).

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

print_step(geo(Problem, Token), I, Id, A) :-
    step_id_text(Id, T),
    step_kind(Id, A, Kind, _),
    (   Kind == manipulation -> Mark = "" ; format(string(Mark), "  [~w]", [Kind]) ),
    py_bridge(step_geometry(Problem, Token, T), G),
    moves_text(G, Moves),
    format("  ~w. ~w: ~q~s~s~n", [I, T, A, Mark, Moves]),
    print_made(G),
    (   get_dict(joints_deg, G, Q), is_list(Q)
    ->  (   get_dict(ik_solver, G, S), S \== @(none)
        ->  format("       joints (deg, ~w IK): ~w~n", [S, Q])
        ;   format("       joints (deg): ~w~n", [Q])
        )
    ;   true
    ),
    (   get_dict(placement, G, P), is_dict(P)
    ->  (   get_dict(on, P, On)
        ->  format(atom(Where), " on ~w", [On])
        ;   Where = ''
        ),
        format("       placement: x=~w y=~w z=~w yaw=~w deg (~w)~w~n",
               [P.x, P.y, P.z, P.yaw_deg, P.pose, Where])
    ;   true
    ).

%   print_made(+Geometry): the mates a product step's insertion makes, in
%   the order this instance took (phase2.mates), and the tightest of their
%   insertion checks, as lengths; nothing for other steps.
print_made(G) :-
    (   get_dict(mates, G, Names), Names = [_|_]
    ->  atomic_list_concat(Names, ', ', Text),
        format("       makes ~w~n", [Text]),
        (   get_dict(tightest, G, T), is_dict(T)
        ->  (   T.satisfied == true -> V = "satisfied" ; V = "NOT satisfied" ),
            format("       tightest: ~w (~w), ~4f of ~w: ~w~n",
                   [T.mate, T.constraint, T.bound, T.threshold, V])
        ;   true
        )
    ;   true
    ).

%   moves_text(+Geometry, -Text): "  moves block + pin_a" when the step moves
%   a subassembly (more than one part), else "".
moves_text(G, Text) :-
    (   get_dict(moves, G, Parts), is_list(Parts), Parts = [_, _|_]
    ->  atomic_list_concat(Parts, ' + ', Joined),
        format(string(Text), "  moves ~w", [Joined])
    ;   Text = ""
    ).

print_verdict(Id0, C) :-
    step_id_text(Id0, Id),
    (   satisfied(C) -> V = "satisfied" ; V = "NOT satisfied" ),
    (   get_dict(kind, C, geometric)
    ->  format("  ~w ~w: ~w (~w)~n", [Id, C.constraint, V, C.description])
    ;   readable(C.threshold, Th),
        (   get_dict(unit, C, U0) -> format(string(U), " ~w", [U0]) ; U = "" ),
        (   get_dict(mate, C, M) -> format(string(Of), " (~w)", [M]) ; Of = "" ),
        format("  ~w ~w~s: bound ~4f~s ~w ~w~s: ~w~n",
               [Id, C.constraint, Of, C.bound, U, C.sense, Th, U, V])
    ).

%   readable(+X, -Y): X rounded to 9 decimals for printing (0.16, not the
%   0.16000000000000003 that 0.4^2 is in floating point).
readable(X, Y) :-
    (   float(X) -> Y is round(X * 1.0e9) / 1.0e9 ; Y = X ).
