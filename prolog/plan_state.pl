/*  spar-py: the phase-1 plan state (Secs. 2, 4): the record the goal loop
    threads through the search, Plan0 -> Plan, and the search recorder.

    A plan state is a term with 18 fields,

      plan(Actions, Order, Net, Ids, Ops, Geos, Sat, Steps, Bound, Methods,
           Trace, History, Checked, Lookahead, Recorder, Seps, Index,
           Pending)

    each with a reader plan_F(+Plan, -Value) and, for those the search
    changes, a writer set_F_of_plan(+Value, +Plan0, -Plan) that checks the
    value's type (library(record)'s names; make_plan/2 builds one). The
    fields, documented at their accessors below: the plan actions, the
    ordering graph (ordering.pl), the geometric network (cms.pl), the
    symbol counters, the operational and geometric goal stacks, the
    satisfied list, the step count, the bound on the number of actions,
    the declobbering methods, the trace flag, the history of the
    operational steps, the geometric goals checked ahead of their turn,
    whether to check them so, the search recorder, the separations and the
    index of the actions' add and delete lists, and the geometric goals
    forward checking left pending.

    Backtracking undoes every change to a plan state but one: goals.pl and
    establish.pl only build new plan terms (and dif/2 constraints, for the
    separations). The exception is the contents of the search recorder,
    failures(DeepestOp, DeepestGeo, BoundHit, Budget-steps(Spent)), which
    record_failure/3, bound_hit/1 and spend_step/1 update with nb_setarg/3
    because it must outlive the failures it records. (The CMS network's
    oracle memo, cms.pl, and the atoms memo of a history entry,
    goals:conflict_steps/3, are the other non-backtrackable state of
    phase 1.)

    goals.pl and establish.pl both use this module, and it uses neither.
*/
:- module(plan_state,
          [ make_plan/2,              % +Fields, -Plan
            % readers
            plan_actions/2, plan_order/2, plan_net/2, plan_ids/2,
            plan_ops/2, plan_geos/2, plan_sat/2, plan_steps/2,
            plan_bound/2, plan_methods/2, plan_trace/2, plan_history/2,
            plan_checked/2, plan_lookahead/2, plan_recorder/2, plan_seps/2,
            plan_index/2, plan_pending/2,
            % writers
            set_actions_of_plan/3, set_order_of_plan/3, set_net_of_plan/3,
            set_ids_of_plan/3, set_ops_of_plan/3, set_geos_of_plan/3,
            set_sat_of_plan/3, set_steps_of_plan/3, set_history_of_plan/3,
            set_checked_of_plan/3, set_recorder_of_plan/3,
            set_seps_of_plan/3, set_index_of_plan/3,
            push_history_of_plan/3, set_pending_of_plan/3,
            % the search recorder
            failure_recorder/2,       % +Budget, -Recorder
            record_failure/3,         % +K, +Goal, +Plan
            bound_hit/1,              % +Plan
            spend_step/1,             % +Plan
            recorder_bound_hit/1,     % +Recorder
            recorder_deepest/3,       % +Recorder, -DeepestOp, -DeepestGeo
            % the trace
            note/3                    % +Plan, +Format, +Args
          ]).
:- use_module(library(error)).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(assoc)).
:- use_module(spar_defaults).
:- use_module(ordering, [empty_ordering/1]).

%!  make_plan(+Fields:list, -Plan) is det.
%
%   Plan is a plan state whose fields are given by Fields, a list of
%   Name(Value) (actions([]), bound(4), ...), in any order; the fields not
%   given have their defaults: [] for the lists, the empty ordering, no
%   goals checked ahead (an empty assoc), 0 steps, the bound,
%   methods, trace flag and forward checking of default_option/2
%   (max_actions_floor, declobber, trace, forward_check), a recorder without a
%   step budget (failure_recorder(0-steps(0), R)) and an unbound network.
%
%   ==
%   ?- make_plan([bound(4)], P), plan_bound(P, B), plan_ops(P, Ops).
%   B = 4, Ops = [].
%   ==
%
%   @error type_error(list, Fields) if Fields is not a list.
%   @error domain_error(plan_field, F) if F is not Name(Value) for a field.
%   @error type_error(T, Value) if Value is not of the field's type T.

make_plan(Fields, Plan) :-
    must_be(list, Fields),
    default_plan(Plan0),
    foldl(set_field, Fields, Plan0, Plan).

default_plan(plan([], Order, _Net, [], [], [], [], 0, Bound, Methods, Trace,
                  [], Checked, Lookahead, Recorder, [], index(Adds, Dels), none)) :-
    empty_ordering(Order),
    empty_assoc(Checked),
    empty_assoc(Adds),
    empty_assoc(Dels),
    default_option(max_actions_floor, Bound),
    default_option(declobber, Methods),
    default_option(trace, Trace),
    default_option(forward_check, Lookahead),
    failure_recorder(0-steps(0), Recorder).

set_field(Field, Plan0, Plan) :-
    (   compound(Field),
        compound_name_arguments(Field, Name, [Value]),
        plan_field(Name, I, Type)
    ->  must_be(Type, Value),
        Plan0 =.. [plan|Args0],
        nth1(I, Args0, _, Rest),
        nth1(I, Args, Value, Rest),
        Plan =.. [plan|Args]
    ;   domain_error(plan_field, Field)
    ).

%   plan_field(?Name, ?Argument, ?Type): the fields, in order.

plan_field(actions,   1, list).
plan_field(order,     2, compound).
plan_field(net,       3, any).
plan_field(ids,       4, list).
plan_field(ops,       5, list).
plan_field(geos,      6, list).
plan_field(sat,       7, list).
plan_field(steps,     8, integer).
plan_field(bound,     9, integer).
plan_field(methods,  10, list).
plan_field(trace,    11, boolean).
plan_field(history,  12, list).
plan_field(checked,  13, assoc).
plan_field(lookahead, 14, boolean).
plan_field(recorder, 15, any).
plan_field(seps,     16, list).
plan_field(index,    17, compound).
plan_field(pending,  18, any).

                 /*******************************
                 *          ACCESSORS           *
                 *******************************/

%!  plan_actions(+Plan, -Actions:list) is det.
%!  set_actions_of_plan(+Actions:list, +Plan0, -Plan) is det.
%
%   The plan actions, newest first, each an instantiated template
%   action(Id, Term, preconditions(Ops, Geos), addlist(Adds), dellist(Dels)).
%   Fig. 23 lists them in this order.
%
%   @error type_error(list, Actions) from set_actions_of_plan/3 if Actions is
%          not a list (instantiation_error if it is unbound or partial).

plan_actions(plan(Actions,_,_,_,_,_,_,_,_,_,_,_,_,_,_,_,_,_), Actions).
set_actions_of_plan(Actions, plan(_,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18),
                    plan(Actions,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18)) :-
    must_be(list, Actions).

%!  plan_order(+Plan, -Order) is det.
%!  set_order_of_plan(+Order, +Plan0, -Plan) is det.
%
%   The ordering graph with its transitive closure (ordering.pl's
%   ord/3; empty_ordering/1 by default).
%
%   @error type_error(compound, Order) from set_order_of_plan/3 if Order
%          is not a compound term (instantiation_error if it is unbound).

plan_order(plan(_,Order,_,_,_,_,_,_,_,_,_,_,_,_,_,_,_,_), Order).
set_order_of_plan(Order, plan(A1,_,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18),
                  plan(A1,Order,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18)) :-
    must_be(compound, Order).

%!  plan_net(+Plan, -Net) is det.
%!  set_net_of_plan(+Net, +Plan0, -Plan) is det.
%
%   The geometric constraint network (cms.pl).

plan_net(plan(_,_,Net,_,_,_,_,_,_,_,_,_,_,_,_,_,_,_), Net).
set_net_of_plan(Net, plan(A1,A2,_,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18),
                plan(A1,A2,Net,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18)).

%!  plan_ids(+Plan, -Ids:list) is det.
%!  set_ids_of_plan(+Ids:list, +Plan0, -Plan) is det.
%
%   The symbol counters of the plan's names (action_N, grasp_N, pos_N,
%   goal_N, ...), threaded by spar_actions:gensym//2.
%
%   @error type_error(list, Ids) from set_ids_of_plan/3 if Ids is
%          not a list (instantiation_error if it is unbound or partial).

plan_ids(plan(_,_,_,Ids,_,_,_,_,_,_,_,_,_,_,_,_,_,_), Ids).
set_ids_of_plan(Ids, plan(A1,A2,A3,_,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18),
                plan(A1,A2,A3,Ids,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18)) :-
    must_be(list, Ids).

%!  plan_ops(+Plan, -Ops:list) is det.
%!  set_ops_of_plan(+Ops:list, +Plan0, -Plan) is det.
%
%   The operational goal stack, op(GoalId, ActionId, Condition) terms,
%   top first.
%
%   @error type_error(list, Ops) from set_ops_of_plan/3 if Ops is
%          not a list (instantiation_error if it is unbound or partial).

plan_ops(plan(_,_,_,_,Ops,_,_,_,_,_,_,_,_,_,_,_,_,_), Ops).
set_ops_of_plan(Ops, plan(A1,A2,A3,A4,_,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18),
                plan(A1,A2,A3,A4,Ops,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18)) :-
    must_be(list, Ops).

%!  plan_geos(+Plan, -Geos:list) is det.
%!  set_geos_of_plan(+Geos:list, +Plan0, -Plan) is det.
%
%   The geometric goal stack, geo(GoalId, ActionId, Constraint,
%   OpConditions) terms, top first.
%
%   @error type_error(list, Geos) from set_geos_of_plan/3 if Geos is
%          not a list (instantiation_error if it is unbound or partial).

plan_geos(plan(_,_,_,_,_,Geos,_,_,_,_,_,_,_,_,_,_,_,_), Geos).
set_geos_of_plan(Geos, plan(A1,A2,A3,A4,A5,_,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18),
                 plan(A1,A2,A3,A4,A5,Geos,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18)) :-
    must_be(list, Geos).

%!  plan_sat(+Plan, -Sat:list) is det.
%!  set_sat_of_plan(+Sat:list, +Plan0, -Plan) is det.
%
%   The satisfied list: sat(Goal, Establisher) for every goal met, newest
%   first; for a geometric goal Establisher is the list of the
%   establishers of its operational conditions.
%
%   @error type_error(list, Sat) from set_sat_of_plan/3 if Sat is
%          not a list (instantiation_error if it is unbound or partial).

plan_sat(plan(_,_,_,_,_,_,Sat,_,_,_,_,_,_,_,_,_,_,_), Sat).
set_sat_of_plan(Sat, plan(A1,A2,A3,A4,A5,A6,_,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18),
                plan(A1,A2,A3,A4,A5,A6,Sat,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18)) :-
    must_be(list, Sat).

%!  plan_steps(+Plan, -Steps:integer) is det.
%!  set_steps_of_plan(+Steps:integer, +Plan0, -Plan) is det.
%
%   The number of goal-loop steps taken on this branch of the search.
%
%   @error type_error(integer, Steps) from set_steps_of_plan/3 if Steps is
%          not an integer (instantiation_error if it is unbound or partial).

plan_steps(plan(_,_,_,_,_,_,_,Steps,_,_,_,_,_,_,_,_,_,_), Steps).
set_steps_of_plan(Steps, plan(A1,A2,A3,A4,A5,A6,A7,_,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18),
                  plan(A1,A2,A3,A4,A5,A6,A7,Steps,A9,A10,A11,A12,A13,A14,A15,A16,A17,A18)) :-
    must_be(integer, Steps).

%!  plan_bound(+Plan, -Bound:integer) is det.
%
%   The largest number of plan actions allowed in this round of
%   iterative deepening.

plan_bound(plan(_,_,_,_,_,_,_,_,Bound,_,_,_,_,_,_,_,_,_), Bound).

%!  plan_methods(+Plan, -Methods:list) is det.
%
%   The declobbering methods, in the order tried (establish.pl).

plan_methods(plan(_,_,_,_,_,_,_,_,_,Methods,_,_,_,_,_,_,_,_), Methods).

%!  plan_trace(+Plan, -Trace:boolean) is det.
%
%   Whether the search prints its steps (note/3).

plan_trace(plan(_,_,_,_,_,_,_,_,_,_,Trace,_,_,_,_,_,_,_), Trace).

%!  plan_history(+Plan, -History:list) is det.
%!  set_history_of_plan(+History:list, +Plan0, -Plan) is det.
%
%   One h(K, Condition, NewActions, Memo) per operational step K on this
%   branch, newest first: the condition as bound, the actions the step
%   added and a memo of their atoms (for conflict-directed backjumping,
%   goals:conflict_steps/3).
%
%   @error type_error(list, History) from set_history_of_plan/3 if History is
%          not a list (instantiation_error if it is unbound or partial).

plan_history(plan(_,_,_,_,_,_,_,_,_,_,_,History,_,_,_,_,_,_), History).
set_history_of_plan(History, plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,_,A13,A14,A15,A16,A17,A18),
                    plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,History,A13,A14,A15,A16,A17,A18)) :-
    must_be(list, History).

%!  push_history_of_plan(+Entry, +Plan0, -Plan) is det.
%
%   Plan is Plan0 with Entry on top of its history. The history is a list
%   already, so nothing is walked: set_history_of_plan/3's check of the
%   whole list at every step would cost the length of the history each
%   time (quadratic over a search of thousands of steps).

push_history_of_plan(Entry, plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,H0,A13,A14,A15,A16,A17,A18),
                     plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,[Entry|H0],A13,A14,A15,A16,A17,A18)).

%!  plan_checked(+Plan, -Checked) is det.
%!  set_checked_of_plan(+Checked, +Plan0, -Plan) is det.
%
%   The ids of the geometric goals already checked ahead of their turn
%   (forward checking), an assoc from each id to `true` (library(assoc):
%   the test is made for every pending goal at every step, so it must not
%   cost the length of the list).
%
%   @error type_error(assoc, Checked) from set_checked_of_plan/3 if
%          Checked is not an assoc.

plan_checked(plan(_,_,_,_,_,_,_,_,_,_,_,_,Checked,_,_,_,_,_), Checked).
set_checked_of_plan(Checked, plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,_,A14,A15,A16,A17,A18),
                    plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,Checked,A14,A15,A16,A17,A18)) :-
    must_be(assoc, Checked).

%!  plan_lookahead(+Plan, -Lookahead:boolean) is det.
%
%   Whether geometric goals are checked ahead of their turn (option
%   forward_check).

plan_lookahead(plan(_,_,_,_,_,_,_,_,_,_,_,_,_,Lookahead,_,_,_,_), Lookahead).

%!  plan_recorder(+Plan, -Recorder) is det.
%!  set_recorder_of_plan(+Recorder, +Plan0, -Plan) is det.
%
%   The search recorder shared by every branch of a phase-1 call (see
%   failure_recorder/2): not undone on backtracking.

plan_recorder(plan(_,_,_,_,_,_,_,_,_,_,_,_,_,_,Recorder,_,_,_), Recorder).
set_recorder_of_plan(Recorder, plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,_,A16,A17,A18),
                     plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,Recorder,A16,A17,A18)).

%!  plan_seps(+Plan, -Seps:list) is det.
%!  set_seps_of_plan(+Seps:list, +Plan0, -Plan) is det.
%
%   The separations sep(D, Cond) posted by declobbering, newest first
%   (establish.pl); each is also a dif/2 constraint on the plan's terms.
%
%   @error type_error(list, Seps) from set_seps_of_plan/3 if Seps is
%          not a list (instantiation_error if it is unbound or partial).

plan_seps(plan(_,_,_,_,_,_,_,_,_,_,_,_,_,_,_,Seps,_,_), Seps).
set_seps_of_plan(Seps, plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,_,A17,A18),
                 plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,Seps,A17,A18)) :-
    must_be(list, Seps).

%!  plan_index(+Plan, -Index) is det.
%!  set_index_of_plan(+Index, +Plan0, -Plan) is det.
%
%   The plan actions by the terms of their add and delete lists,
%   index(Adds, Dels), two assocs from a term key (establish.pl's
%   term_key/2) to b(Bits, Entries), Entries the actions with such a
%   term, c(Id, Bit, Terms) newest first (Bit the action's bit in the
%   ordering, Terms its add or delete list), Bits the union of their
%   bits: establish.pl finds an establisher or a possible clobberer of a
%   condition among the actions under its key, not among all of them.
%   Kept by establish:add_action/5, the one place an action enters the
%   plan.
%
%   @error type_error(compound, Index) from set_index_of_plan/3 if Index
%          is not a compound term.

plan_index(plan(_,_,_,_,_,_,_,_,_,_,_,_,_,_,_,_,Index,_), Index).
set_index_of_plan(Index, plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,_,A18),
                  plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,Index,A18)) :-
    must_be(compound, Index).

%!  plan_pending(+Plan, -Pending) is det.
%!  set_pending_of_plan(+Pending, +Plan0, -Plan) is det.
%
%   What the last forward check on this branch left for the next
%   (goals.pl): `none`, or seen(Geos, Left), Geos the geometric stack it
%   scanned and Left the goals of Geos it did not check (not ground yet,
%   or on a variable without a node), in stack order. Every other goal of
%   Geos is in the checked assoc, so the next check need only scan what
%   was pushed on top of Geos since, and Left.

plan_pending(plan(_,_,_,_,_,_,_,_,_,_,_,_,_,_,_,_,_,Pending), Pending).
set_pending_of_plan(Pending, plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,_),
                    plan(A1,A2,A3,A4,A5,A6,A7,A8,A9,A10,A11,A12,A13,A14,A15,A16,A17,Pending)).

                 /*******************************
                 *       THE SEARCH RECORDER    *
                 *******************************/

%!  failure_recorder(+Budget, -Recorder) is det.
%
%   A new recorder failures(none, none, false, Budget): no operational
%   and no geometric goal has failed yet, the bound has refused no
%   action, and Budget = Max-steps(Spent) counts the goal steps against
%   Max (0: no budget). A phase-1 call shares one Budget among the
%   recorders of its rounds.
%
%   @error domain_error(step_budget, Budget) if Budget is not
%          Max-steps(Spent) with integers Max and Spent.

failure_recorder(Budget, failures(none, none, false, Budget)) :-
    (   Budget = Max-steps(Spent), integer(Max), integer(Spent)
    ->  true
    ;   domain_error(step_budget, Budget)
    ).

%!  record_failure(+K, +Goal, +Plan) is det.
%
%   Goal, considered at step K, had no way to be satisfied: keep it in
%   Plan's recorder if no goal of its kind (operational, geometric) failed
%   at a deeper step. Survives backtracking (nb_setarg/3).

record_failure(K, Goal, Plan) :-
    plan_recorder(Plan, Recorder),
    (   Goal = geo(_, _, _, _) -> Arg = 2 ; Arg = 1 ),
    arg(Arg, Recorder, Old),
    (   ( Old == none ; Old = K0-_, K > K0 )
    ->  copy_term(Goal, Kept, _),       % without the dif/2 constraints, which
        nb_setarg(Arg, Recorder, K-Kept) % nb_setarg/3 would copy whole
    ;   true
    ).

%!  bound_hit(+Plan) is det.
%
%   Note in Plan's recorder that the bound refused a new action in this
%   round. Survives backtracking (nb_setarg/3).

bound_hit(Plan) :-
    plan_recorder(Plan, Recorder),
    nb_setarg(3, Recorder, true).

%!  spend_step(+Plan) is det.
%
%   Count a goal step against the budget of Plan's recorder (shared by
%   all rounds of a phase-1 call; survives backtracking).
%
%   @throws spar_step_budget when the budget is spent.

spend_step(Plan) :-
    plan_recorder(Plan, Recorder),
    arg(4, Recorder, Budget-Spent),
    arg(1, Spent, N0),
    N is N0 + 1,
    nb_setarg(1, Spent, N),
    (   Budget > 0, N > Budget
    ->  throw(spar_step_budget)
    ;   true
    ).

%!  recorder_bound_hit(+Recorder) is semidet.
%
%   The bound refused an action since Recorder was made.

recorder_bound_hit(failures(_, _, true, _)).

%!  recorder_deepest(+Recorder, -DeepestOp, -DeepestGeo) is det.
%
%   The operational and the geometric goal that failed at the deepest
%   step, each K-Goal (K the step), or none.

recorder_deepest(failures(Op, Geo, _, _), Op, Geo).

                 /*******************************
                 *            TRACE             *
                 *******************************/

%!  note(+Plan, +Format, +Args) is det.
%
%   Print format(Format, Args) to current output if Plan traces.

note(Plan, Format, Args) :-
    (   plan_trace(Plan, true)
    ->  format(Format, Args)
    ;   true
    ).
