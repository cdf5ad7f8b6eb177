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
          [ phase2/3,              % +Partial, +Options, -Result
            check_instance/2,      % +Steps, -Augmented
            instance_steps/3       % +Instance, -Steps, -Bindings
          ]).
:- use_module(library(apply)).
:- use_module(library(lists)).
:- use_module(library(option)).
:- use_module(library(error)).
:- use_module(library(yall)).
:- use_module(foreign, [py_bridge/2]).
:- use_module('../kb/templates/sensing', []).

%!  phase2(+Partial, +Options, -Result) is det.
%
%   Result = ur(Best, Examined, Cap, Complete), or no_instance(Examined, Cap,
%   Complete) when no instance could be executed at all (every one needed
%   a put-down with no reachable placement). Best is an augmented instance
%   aug(Steps, ErrorCount, Verifications, Recoveries, Verdicts, Geometry,
%   Bindings) (see check_instance/2); Examined the instances checked;
%   Complete true if the partial plan has no further instance.
%   Options: max_instances(Cap) (default 50).

phase2(Partial, Options, Result) :-
    option(max_instances(Cap), Options, 50),
    must_be(positive_integer, Cap),
    State = best(none, inf, 0, false),
    (   once(( limit(Cap, spar:partial_instances(Partial, Instance)),
               examine(Instance, State, Aug),
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

examine(Instance, State, Aug) :-
    arg(3, State, N0), N is N0 + 1, nb_setarg(3, State, N),
    instance_steps(Instance, Steps, Bindings),
    check_instance(Steps, aug(S, E, V, R, C, G)),
    Aug = aug(S, E, V, R, C, G, Bindings),
    arg(2, State, BestE),
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

%!  check_instance(+Steps, -Augmented) is semidet.
%
%   Steps is a list of step(Id, Action) in execution order. Augmented is
%   aug(Steps1, ErrorCount, Verifications, Recoveries, Verdicts, Geometry):
%   Steps1 with sensing and squeezes inserted; Verdicts a list of
%   verdict(Id, Action, Dicts) (Python's verdict dicts: constraint, bound,
%   threshold, satisfied, ...); Geometry a list of Id-Dict (tool pose, joint
%   angles, placement). Fails if the instance cannot be executed at all (a
%   geometric precondition fails: no placement, no joint solution).

check_instance(Steps, aug(Final, Errors, Verifs, Recovs, Verdicts, Geometry)) :-
    must_be(list, Steps),
    remedy_loop(Steps, [], Final, Failed, Verdicts, Geometry),
    length(Failed, Errors),
    maplist(failed_step(Final), Failed, FailedSteps),
    maplist(verification, FailedSteps, Verifs),
    maplist(recovery, FailedSteps, Recovs).

failed_step(Steps, Id, step(Id, A)) :-
    memberchk(step(Id, A), Steps).

%   remedy_loop(+Steps, +GivenUp, -Final, -Failed, -Verdicts, -Geometry):
%   run the steps; at the first failing action not yet given up, try the
%   remedies in order; an action no remedy helps is given up (it counts as
%   an error) and the run goes on past it.

remedy_loop(Steps, GivenUp, Final, Failed, Verdicts, Geometry) :-
    run(Steps, GivenUp, Result),
    (   Result = ok(Verdicts, Geometry)
    ->  Final = Steps, reverse(GivenUp, Failed)
    ;   Result = failed(Step, Before)
    ->  (   remedy(Step, Before, Steps, GivenUp, Steps1)
        ->  remedy_loop(Steps1, GivenUp, Final, Failed, Verdicts, Geometry)
        ;   Step = step(Id, _),
            remedy_loop(Steps, [Id|GivenUp], Final, Failed, Verdicts, Geometry)
        )
    ).

%   run(+Steps, +GivenUp, -Result): propagate the world through Steps.
%   Result = ok(Verdicts, Geometry); failed(Step, Prefix) for the first
%   action whose uncertainty-reduction preconditions are not all satisfied
%   and that is not in GivenUp; infeasible(Step) if a geometric
%   precondition fails (the run cannot go on; the caller fails).

run(Steps, GivenUp, Result) :-
    maplist(step_dict, Steps, Dicts),
    py_bridge(ur_world(Dicts), W0),
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
    (   member(C, Checks), get_dict(kind, C, geometric), get_dict(satisfied, C, false)
    ->  Result = infeasible(Step)
    ;   \+ all_satisfied(Checks), \+ memberchk(Id, GivenUp)
    ->  reverse(Prefix, Before), Result = failed(Step, Before)
    ;   run(Rest, GivenUp, W1, [Step|Prefix], Vs1, [Id-Geo|Gs0], Result)
    ).

all_satisfied(Checks) :-
    forall(member(C, Checks), get_dict(satisfied, C, true)).

%   remedy(+Failing, +Before, +Steps, +GivenUp, -Steps1): the first remedy
%   of Sec. 4.3 that makes Failing's preconditions hold.

remedy(step(Id, pickup(Obj, _)), _, Steps, GivenUp, Steps1) :-
    \+ inserted_for(Id, Steps),
    insert_before(Id, [step(sense(Id, 1), dense_range_scan(Obj))], Steps, Steps1),
    passes(Id, Steps1, GivenUp).
remedy(step(Id, assemble(O1, O2, _, _, _)), Before, Steps, GivenUp, Steps1) :-
    \+ inserted_for(Id, Steps),
    establisher_of_holding(O1, Before, EId),
    Scans = [ step(sense(Id, 1), dense_range_scan(O1)),
              step(sense(Id, 2), dense_range_scan(O2)) ],
    (   insert_before(EId, Scans, Steps, Steps1),
        passes(Id, Steps1, GivenUp)
    ->  true
    ;   append(Scans, [step(squeeze(Id), squeeze(O2))], WithSqueeze),
        insert_before(EId, WithSqueeze, Steps, Steps1),
        passes(Id, Steps1, GivenUp)
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

%   passes(+Id, +Steps, +GivenUp): with Steps, action Id's preconditions
%   hold (the run gets past Id).
passes(Id, Steps, GivenUp) :-
    run(Steps, GivenUp, Result),
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
