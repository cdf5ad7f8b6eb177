/*  spar-py: the phase-1 loop (Secs. 2, 3.4, 4.2): goal stacks, the
    satisfied list, geometric goals and the bound on plan size.

    Goals (Sec. 3.4) are

      op(GoalId, ActionId, Condition)                 operational
      geo(GoalId, ActionId, Constraint, OpConditions) geometric

    to be satisfied just before action ActionId; the user's goals are
    op(top_N, finish, Goal), `finish` being the virtual last action.

    The plan state is the plan/18 record of plan_state.pl, threaded
    through the search (Plan0 -> Plan): the plan actions (newest first, as
    Fig. 23 lists them), the ordering graph, the geometric network, the
    goal stacks, the satisfied list of sat(Goal, Establisher) entries, the
    separations and the rest, described there. Every planner choice is a
    Prolog choice point; backtracking undoes it completely, symbol numbers
    included. Three things outlive backtracking, on purpose: the search
    recorder in the plan (plan_state.pl: the deepest failures, whether the
    bound refused an action, the step budget; nb_setarg/3), the memo of
    arc pairs in the CMS network (cms.pl; nb_setarg/3), and the atoms a
    history entry mentions (conflict_steps/3; nb_setarg/3, kept with a
    copy of the term they were found in and used only while the entry is
    still == that copy, so that backtracking cannot make them stale).

    The loop (Sec. 2): take the first goal of the operational stack, else of
    the geometric stack; satisfy it (establish.pl for operational goals,
    satisfy_geo/3 here for geometric ones); repeat until both stacks are
    empty. A geometric goal is a committed call on the CMS: if the CMS
    refuses, the goal fails and the search returns to the establishment of
    the operational goals, whose next alternative is a new action (Sec.
    4.2: the putdown(block, pos_1) of Sec. 6). It returns straight to the
    latest step that could change the CMS's answer (conflict-directed
    backjumping, see step/3), and a geometric goal is checked as soon as its
    variables are bound (forward checking); both find the same plans and
    keep the search of unsolvable problems short.

    Depth first search with a bound on the number of plan actions, raised
    from a lower bound on the plan size (lower_bound/2) to max_actions one
    step at a time (iterative deepening): the first plan found is a
    smallest one, and an unsolvable problem ends, reporting the goal that
    failed at the deepest point of the last round (a geometric goal the
    CMS refused, if any). A round that never met the bound ends the search
    at once. Planning of this kind is exponential in the plan size (Sec.
    7.2) and undecidable (Sec. 2), so a budget of steps over all rounds
    (max_steps, by default derived from the problem's size; the defaults
    are spar_defaults.pl's) keeps even a hard unsolvable problem short;
    when it is spent, the outcome names the last bound searched
    completely.
*/
:- module(goals,
          [ phase1_search/3,         % +Options, -Outcome, -Bound
            max_action_bound/2,      % +Options, -Max
            initial_plan/3,          % +Bound, +Options, -Plan
            solve/2,                 % +Plan0, -Plan
            satisfy_geo/3,           % +Goal, +Plan0, -Plan
            plan_partial/2,          % +Plan, -Partial
            print_goal/1,            % +Goal
            print_action/1,          % +Action
            conflict_steps/3         % +Vars, +Plan, -Ks
          ]).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(error)).
:- use_module(library(option)).
:- use_module(library(yall)).
:- use_module(library(ordsets)).
:- use_module(library(assoc)).
:- use_module(kb, []).
:- use_module(ordering).
:- use_module(cms).
:- use_module(establish).
:- use_module(plan_state).
:- use_module(spar_defaults).
:- use_module(spar_paths, []).    % the file search path spar
:- use_module(spar(kb/templates/spar_actions),
              [gensym//2, mating_grasps/4, assembly_turn/3]).

%!  phase1_search(+Options, -Outcome, -Bound) is det.
%
%   Iterative deepening over the bound on plan size, from lower_bound/2
%   to max_actions (auto, the default: derived from the lower bound by
%   spar_defaults:derived_max_actions/2). Outcome is plan(Partial) for
%   the first plan found, Bound the bound it was found at; otherwise
%   Outcome is no_plan(Bound, UnmetGoal), UnmetGoal the goal that failed
%   at the deepest step of the last round searched completely (see
%   unmet_goal/2) and Bound = max_actions, or the last bound searched
%   completely if the step budget ran out. Options are checked by
%   spar:phase1/3.

phase1_search(Options, Outcome, Bound) :-
    must_be(list, Options),
    default_option(max_steps, Budget0),
    option(max_steps(Budget1), Options, Budget0),
    run_oracle(Options, Oracle),        % one memo for the run: the lower
    lower_bound_(Oracle, LB),           % bound's arcs are the search's too
    max_action_bound(Options, LB, Max),
    (   Budget1 == auto
    ->  derived_max_steps(LB, Budget)
    ;   Budget = Budget1
    ),
    Lo is min(LB, Max),
    Spent = steps(0),
    rounds(Lo, Max, Budget-Spent, none, [run_oracle(Oracle)|Options], Outcome, Bound).

%   run_oracle(+Options, -Oracle): the memoised oracle (cms_oracle/2) of
%   a run with Options: of their oracle(Closure), else of
%   foreign:arc_pairs/5.

run_oracle(Options, Oracle) :-
    (   option(oracle(Closure), Options)
    ->  true
    ;   Closure = foreign:arc_pairs
    ),
    cms_oracle(Closure, Oracle).

%!  max_action_bound(+Options, -Max) is det.
%
%   The largest bound phase1_search/3 tries for the loaded problem with
%   Options: max_actions(N), or derived from lower_bound/2 for
%   max_actions(auto) (the default; spar_defaults:derived_max_actions/2).

max_action_bound(Options, Max) :-
    must_be(list, Options),
    default_option(max_actions, Max0),
    option(max_actions(Max1), Options, Max0),
    (   Max1 == auto
    ->  lower_bound(Options, LB),
        derived_max_actions(LB, Max)
    ;   Max = Max1
    ).

%   max_action_bound(+Options, +LB, -Max): max_action_bound/2 given the
%   lower bound LB (phase1_search/3 has computed it).

max_action_bound(Options, LB, Max) :-
    default_option(max_actions, Max0),
    option(max_actions(Max1), Options, Max0),
    (   Max1 == auto
    ->  derived_max_actions(LB, Max)
    ;   Max = Max1
    ).

%!  lower_bound(+Options, -N) is det.
%
%   A lower bound on the number of actions any plan needs, where iterative
%   deepening starts (at least 1), admissible: each user goal not true
%   initially needs at least one action of its own (its last); a goal
%   assembled(Peg, Hole, [_, HoleFaces], Ta, _) needs the assemble and a
%   pickup of Peg (a pickup serves one assemble: it is the last pickup
%   of Peg before it); and each Hole object that must leave its initial
%   position before it can be mated needs a pickup and a putdown of it,
%   counted once however many goals mate with it: it rests there in a
%   stable pose hiding a face of the HoleFaces of some goal (Sec. 6: the
%   block on its hole), or no grasp of that goal's Peg mates with it there
%   (the oracle's mate_reachable(Ta) pairs at that position are none: a
%   block on its side, whose mated peg would enter the table). No action
%   is counted twice, so the sum never exceeds the size of a smallest plan,
%   and starting there finds the same first plan as starting from 1,
%   without the rounds that must fail. Options give the oracle (as
%   initial_plan/3: oracle(Closure), else foreign:arc_pairs/5).

lower_bound(Options, N) :-
    run_oracle(Options, Oracle),
    lower_bound_(Oracle, N).

%   lower_bound_(+Oracle, -N): lower_bound/2 asking Oracle (cms_oracle/2).

lower_bound_(Oracle, N) :-
    findall(K, ( kb:goal(G), goal_lower_bound(G, K) ), Ks),
    sum_list(Ks, N0),
    findall(H, moved_hole(Oracle, H), Hs),
    length(Hs, N1),
    N is max(1, N0 + 2 * N1).

goal_lower_bound(G, 0) :-
    kb:initial(G),
    !.
goal_lower_bound(assembled(_, _, _, _, _), 2) :-
    !.
goal_lower_bound(_, 1).

%   moved_hole(+Oracle, -Hole): (Oracle a cms_oracle/2) Hole (each once) is the hole part of a user
%   goal not true initially that must leave its initial position before
%   the assemble (see lower_bound/2). The oracle (the kinematics) is asked
%   only about a hole whose pose hides none of the goal's faces and whose
%   approach (the goal's V_a, in the hole's frame) does not point down
%   there: the usual hole-up start is not probed, so its arcs (and the
%   refusals a no-plan reports) are the search's own.

moved_hole(Oracle, Hole) :-
    findall(H, ( kb:goal(G),
                 \+ kb:initial(G),
                 G = assembled(Peg, H, [PegFaces, HoleFaces], Ta, Va),
                 kb:initial(part_location(H, Pos)),
                 kb:position(Pos, H, Label, tm(Rows)),
                 kb:position_class(Label, Pose),
                 kb:pose(H, Pose, _, ofaces(Hidden), _),
                 (   once(( member(F, HoleFaces), memberchk(F, Hidden) ))
                 ->  true
                 ;   \+ approach_down(Va, Rows),
                     no_mate_at(Oracle, Peg-PegFaces, H, Ta, Pose, Label)
                 ) ),
            Hs),
    sort(Hs, Holes),
    member(Hole, Holes).

%   approach_down(+Va, +Rows): the vector named Va (hole frame), turned by
%   the rotation of the position's tm Rows (the paper's row form: the
%   images of the object's axes), points down (z below -0.7 of its length).

approach_down(Va, [Rx, Ry, Rz|_]) :-
    atom(Va),
    kb:vector(Va, [X, Y, Z]),
    Rx = [_, _, Zx], Ry = [_, _, Zy], Rz = [_, _, Zz],
    W is X * Zx + Y * Zy + Z * Zz,
    L is sqrt(X * X + Y * Y + Z * Z),
    L > 0,
    W < -0.7 * L.

%   no_mate_at(+Oracle, +Peg-PegFaces, +Hole, +Ta, +Pose, +Label): the
%   assemble for the goal could not happen with Hole at its absolute
%   position Label (in stable pose Pose): for every turn of Ta that allows
%   Pose (spar_actions:assembly_turn/3), the oracle's mate_reachable pairs of
%   Peg's mating grasps at Label are none.

no_mate_at(Oracle, Peg-PegFaces, Hole, Ta, Pose, Label) :-
    atom(Ta),
    mating_grasps(Peg, PegFaces, Ta, Gs0),
    sort(Gs0, Gs),
    Gs \== [],
    \+ ( assembly_turn(Ta, Turn, Allowed),
         ( Allowed == all -> true ; memberchk(Pose, Allowed) ),
         cms_ask(Oracle, mate_reachable(Turn), Peg-Hole, Gs, [Label], Pairs),
         Pairs \== [] ).

%   rounds(+B, +Max, +Budget, +Unmet0, +Options, -Outcome, -Bound): search
%   with bound B, then B+1, ...; stop early when a round failed without
%   the bound ever refusing an action (a larger bound would search the
%   same tree), or when the step budget is spent (then the last bound
%   searched completely is reported, with its unmet goal Unmet0).

rounds(B, Max, Budget, Unmet0, Options, Outcome, Bound) :-
    failure_recorder(Budget, Recorder),
    initial_plan(B, Options, Plan0),
    set_recorder_of_plan(Recorder, Plan0, Plan1),
    note(Plan1, "~n=== phase 1, at most ~d actions ===~n", [B]),
    catch(( solve(Plan1, Plan) -> Found = true ; Found = false ),
          spar_step_budget, Found = budget),
    (   Found == true
    ->  plan_partial(Plan, Partial),
        Outcome = plan(Partial),
        Bound = B
    ;   Found == false,
        B < Max,
        recorder_bound_hit(Recorder)
    ->  B1 is B + 1,
        unmet_goal(Recorder, Unmet1),
        rounds(B1, Max, Budget, Unmet1, Options, Outcome, Bound)
    ;   (   Found == budget
        ->  Bound is B - 1,
            note(Plan1, "~nstep budget spent at bound ~d~n", [B]),
            (   Unmet0 == none -> unmet_goal(Recorder, Unmet) ; Unmet = Unmet0 )
        ;   Bound = Max,
            unmet_goal(Recorder, Unmet)
        ),
        note(Plan1, "~nno plan of at most ~d actions: ~q~n", [Bound, Unmet]),
        Outcome = no_plan(Bound, Unmet)
    ).

%   unmet_goal(+Recorder, -Goal): the geometric goal the CMS refused at the
%   deepest step, else the operational goal that failed at the deepest
%   step (a refusal is a reason in itself, while an operational goal often
%   fails only because the bound allowed no further action), else the
%   first user goal.

unmet_goal(Recorder, Unmet) :-
    recorder_deepest(Recorder, Op, Geo),
    (   Geo = _-Goal
    ->  Unmet = Goal
    ;   Op = _-Goal
    ->  Unmet = Goal
    ;   findall(G, kb:goal(G), [G1|_]),
        Unmet = op(top_1, finish, G1)
    ).

%!  initial_plan(+Bound, +Options, -Plan) is det.
%
%   The null plan: no actions, the user's goals (kb:goal/1, in order) on
%   the operational stack as op(top_N, finish, Goal), at most Bound
%   actions, and a recorder without a step budget (phase1_search/3 gives
%   each round its own recorder). Options (spar:phase1/3's; the defaults are
%   spar_defaults.pl's): declobber(Methods), trace(Bool),
%   forward_check(Bool) and oracle(Closure) for the CMS (cms_empty/2),
%   or run_oracle(Oracle), a memoised oracle (cms_oracle/2) the network
%   shares with the rest of the run (phase1_search/3 gives all its rounds
%   and its lower bound one).
%
%   @error type_error(nonneg, Bound), type_error(list, Options).

initial_plan(Bound, Options, Plan) :-
    must_be(nonneg, Bound),
    must_be(list, Options),
    default_option(declobber, Methods0),
    default_option(trace, Trace0),
    default_option(forward_check, Lookahead0),
    option(declobber(Methods), Options, Methods0),
    option(trace(Trace), Options, Trace0),
    option(forward_check(Lookahead), Options, Lookahead0),
    (   option(run_oracle(Oracle), Options)
    ->  true
    ;   run_oracle(Options, Oracle)
    ),
    cms_empty_with(Oracle, Net),
    findall(G, kb:goal(G), Goals),
    foldl(top_goal, Goals, Tops, [], Ids),
    make_plan([ net(Net), ids(Ids), ops(Tops), bound(Bound),
                methods(Methods), trace(Trace), lookahead(Lookahead) ],
              Plan).

top_goal(G, op(Id, finish, G), Ids0, Ids) :-
    gensym(top_, Id, Ids0, Ids).

%!  solve(+Plan0, -Plan) is nondet.
%
%   The loop of Sec. 2: Plan satisfies every goal of Plan0's stacks.
%   Operational goals first; geometric goals only when the operational
%   stack is empty.

solve(Plan0, Plan) :-
    catch(solve_(Plan0, Plan), backjump(_), fail).

solve_(Plan0, Plan) :-
    plan_ops(Plan0, Ops),
    plan_geos(Plan0, Geos),
    (   Ops = [Goal|Rest]
    ->  trace_step(Goal, Plan0),
        set_ops_of_plan(Rest, Plan0, Plan1),
        step(Goal, Plan1, Plan)
    ;   Geos = [Goal|Rest]
    ->  trace_step(Goal, Plan0),
        set_geos_of_plan(Rest, Plan0, Plan1),
        step(Goal, Plan1, Plan)
    ;   note(Plan0, "~nall goals satisfied~n", []),
        Plan = Plan0
    ).

%   step(+Goal, +Plan0, -Plan): one iteration of the loop, then the rest of
%   the loop (so that a later step can jump back here).
%
%   A goal without any way to satisfy it is recorded (its step and
%   bindings) as the search backtracks. An operational goal backtracks
%   chronologically. A geometric goal the CMS refuses jumps back
%   (conflict-directed backjumping) to the latest step whose choice could
%   make the CMS answer differently, skipping the choice points of the
%   steps in between, which can only add actions and constraints and so
%   can never turn the refusal into success (conflict_steps/3).

step(Goal, Plan0, Plan) :-
    spend_step(Plan0),
    plan_steps(Plan0, K0),
    K is K0 + 1,
    set_steps_of_plan(K, Plan0, Plan1),
    step(Goal, K, Plan1, Plan).

step(Goal, K, Plan0, Plan) :-
    Goal = op(_, _, _),
    (   satisfy_op(Goal, Plan0, Plan1)
    *-> (   true
        ;   note(Plan0, "step ~d: backtracking into ~q~n", [K, Goal]),
            fail
        ),
        add_history(K, Goal, Plan0, Plan1, Plan2),
        forward_check(K, Plan2, Plan3),
        catch(solve_(Plan3, Plan), backjump(Ks), jump(K, Ks, Plan0))
    ;   note(Plan0, "step ~d: cannot satisfy ~q~n", [K, Goal]),
        record_failure(K, Goal, Plan0),
        fail
    ).
step(Goal, K, Plan0, Plan) :-
    Goal = geo(_, _, _, _),
    geo_step(Goal, Plan0, Result),
    (   Result = ok(Plan1)
    ->  solve_(Plan1, Plan)
    ;   Result = refused(Vars),
        record_failure(K, Goal, Plan0),
        conflict_steps(Vars, Plan0, Ks),
        note(Plan0, "step ~d: cannot satisfy ~q, backjump to one of steps ~w~n",
             [K, Goal, Ks]),
        throw(backjump(Ks))
    ).

%   forward_check(+K, +Plan0, -Plan): every pending geometric goal whose
%   variables are all bound must still be acceptable to the CMS. The
%   network only grows tighter, so a refusal now is a refusal when the
%   goal's turn comes: cutting the branch here finds the same first plan
%   sooner. A refusal fails step K's choice if it is among the causes,
%   else jumps back to them.

forward_check(_, Plan0, Plan) :-
    plan_lookahead(Plan0, false),
    !,
    Plan = Plan0.
forward_check(K, Plan0, Plan) :-
    plan_geos(Plan0, Geos),
    plan_net(Plan0, Net),
    plan_checked(Plan0, Checked0),
    plan_pending(Plan0, Pending),
    to_scan(Pending, Geos, Scan),
    unchecked_ground(Scan, Checked0, Net, ToCheck, Left),
    (   member(Goal, ToCheck),
        Goal = geo(_, _, Constraint, Conds),
        geo_objects(Constraint, Conds, Objects),
        cms_try(Constraint, Objects, Net, refused(_, Vars))
    ->  record_failure(K, Goal, Plan0),
        conflict_steps(Vars, Plan0, Ks),
        note(Plan0, "  forward check: the CMS would refuse ~q, back to ~w~n",
             [Constraint, Ks]),
        (   memberchk(K, Ks)
        ->  fail
        ;   throw(backjump(Ks))
        )
    ;   foldl([geo(Id, _, _, _), C0, C]>>put_assoc(Id, C0, true, C),
              ToCheck, Checked0, Checked),
        set_checked_of_plan(Checked, Plan0, Plan1),
        set_pending_of_plan(seen(Geos, Left), Plan1, Plan)
    ).

%   to_scan(+Pending, +Geos, -Scan): the goals of Geos that may be due a
%   forward check, in stack order: those pushed on top of the stack the
%   last check saw and the goals it left (plan_state:plan_pending/2), or
%   the whole stack if it is not that stack with goals pushed on top.

to_scan(seen(Seen, Left), Geos, Scan) :-
    pushed_on(Geos, Seen, Scan, Left),
    !.
to_scan(_, Geos, Geos).

pushed_on(Geos, Seen, Scan, Left) :-
    (   Geos == Seen
    ->  Scan = Left
    ;   Geos = [G|Geos1],
        Scan = [G|Scan1],
        pushed_on(Geos1, Seen, Scan1, Left)
    ).

%   A goal is checked ahead once, as soon as its variables are bound: the
%   network does not change on operational steps (they only add nodes).

%   unchecked_ground(+Geos, +Checked, +Net, -ToCheck, -Left): the goals of
%   Geos not checked yet whose constraint is ground, on variables with
%   nodes, and the others (ToCheck once checked goes into Checked, so Left
%   is all of Geos not in Checked then)
%   (a plain recursion: include/3 would make a meta-call per pending goal
%   at every step).

unchecked_ground([], _, _, [], []).
unchecked_ground([G|Gs], Checked, Net, ToCheck, Left) :-
    G = geo(Id, _, Constraint, _),
    (   \+ get_assoc(Id, Checked, _),
        ground(Constraint),
        constraint_vars(Constraint, Vs),
        forall(member(V, Vs), cms_node(Net, V, _))
    ->  ToCheck = [G|ToCheck1],
        Left = Left1
    ;   ToCheck = ToCheck1,
        Left = [G|Left1]
    ),
    unchecked_ground(Gs, Checked, Net, ToCheck1, Left1).

constraint_vars(member(V, _), [V]).
constraint_vars(in_position_class(V, _), [V]).
constraint_vars(reachable(G, P), [G, P]).
constraint_vars(mate_reachable(G, P, _), [G, P]).

jump(K, Ks, Plan) :-
    (   memberchk(K, Ks)
    ->  fail
    ;   note(Plan, "  step ~d skipped~n", [K]),
        throw(backjump(Ks))
    ).

%   add_history(+K, +Goal, +Plan0, +Plan1, -Plan): remember what step K
%   decided for an operational goal: its condition as bound and the
%   actions it added, h(K, Cond, NewActions, Memo), Memo the memo of
%   conflict_steps/3.

add_history(K, Goal, Plan0, Plan1, Plan) :-
    (   Goal = op(_, _, Cond)
    ->  plan_actions(Plan0, As0),
        plan_actions(Plan1, As1),
        (   As1 == As0
        ->  NewActions = []
        ;   length(As0, N0),
            length(New, N0),
            append(NewActions, New, As1)
        ),
        push_history_of_plan(h(K, Cond, NewActions, atoms(none)), Plan1, Plan)
    ;   Plan = Plan1
    ).

%!  conflict_steps(+Vars, +Plan, -Ks) is det.
%
%   The steps whose choices may have caused a CMS refusal that depends
%   only on the constraints on the network variables Vars (cms_try/4):
%   only a step that bound one of Vars (its condition mentions it) or
%   added an action mentioning one can change those constraints; every
%   other choice only adds actions, orderings and constraints elsewhere,
%   and more constraints never turn a refusal into success. Ks is in
%   decreasing order.

conflict_steps(Vars, Plan, Ks) :-
    plan_history(Plan, History),
    conflict_steps_(History, Vars, Ks).

%   conflict_steps_(+History, +Vars, -Ks): a plain recursion (the tests
%   bind nothing), not findall/3 over member/2: a redo per step of a
%   history of thousands.

conflict_steps_([], _, []).
conflict_steps_([h(K, Cond, New, Memo)|Hs], Vars, Ks) :-
    (   step_mentions_any(Cond, New, Memo, Vars)
    ->  Ks = [K|Ks1]
    ;   Ks = Ks1
    ),
    conflict_steps_(Hs, Vars, Ks1).

%   step_mentions_any(+Term, +Memo, +Vars): the step's Term mentions one
%   of Vars. Every refusal walks the whole history (thousands of steps at
%   N = 50 generated parts), so once a step's term is ground, its atoms
%   are kept in Memo, atoms(Copy-Atoms) (nb_setarg/3: the test is made
%   inside findall/3), with a copy of the term they are the atoms of; they
%   serve while the term is still == that copy (a comparison in C, not a
%   walk in Prolog), and are found again when backtracking and other
%   bindings have changed it.

step_mentions_any(Cond-New, Memo, Vars) :-
    step_mentions_any(Cond, New, Memo, Vars).

%   step_mentions_any(+Cond, +New, +Memo, +Vars): as step_mentions_any/3
%   for the term Cond-New, without building it when the memo answers.

step_mentions_any(Cond, New, Memo, Vars) :-
    (   arg(1, Memo, (Cond0-New0)-Atoms),
        Cond0 == Cond,
        New0 == New
    ->  some_in(Vars, Atoms)
    ;   Term = Cond-New,
        ground(Term)
    ->  term_atoms(Term, Atoms0, []),
        sort(Atoms0, Atoms),
        nb_setarg(1, Memo, Term-Atoms),
        some_in(Vars, Atoms)
    ;   mentions_any(Cond-New, Vars)
    ).

%   some_in(+Vars, +Atoms): one of Vars (a few network variables) is in
%   the ordset Atoms (ord_memberchk/2 is a built-in: no merge of the two
%   lists in Prolog).

some_in([V|Vs], Atoms) :-
    (   ord_memberchk(V, Atoms)
    ->  true
    ;   some_in(Vs, Atoms)
    ).

%   term_atoms(+Term, -Atoms, ?Tail): the atoms of Term, a difference list.

term_atoms(T, As0, As) :-
    (   atom(T)
    ->  As0 = [T|As]
    ;   compound(T)
    ->  compound_name_arity(T, _, N),
        term_atoms(1, N, T, As0, As)
    ;   As0 = As
    ).

term_atoms(I, N, T, As0, As) :-
    (   I > N
    ->  As0 = As
    ;   arg(I, T, A),
        term_atoms(A, As0, As1),
        I1 is I + 1,
        term_atoms(I1, N, T, As1, As)
    ).

mentions_any(Term, Atoms) :-
    (   atom(Term)
    ->  ord_memberchk(Term, Atoms)
    ;   compound(Term),
        compound_name_arity(Term, _, N),
        mentions_any(1, N, Term, Atoms)
    ).

mentions_any(I, N, Term, Atoms) :-
    I =< N,
    arg(I, Term, A),
    (   mentions_any(A, Atoms)
    ->  true
    ;   I1 is I + 1,
        mentions_any(I1, N, Term, Atoms)
    ).

%   satisfy_op(+Goal, +Plan0, -Plan): Sec. 4.1, establishment then
%   declobbering (establish.pl); the possible clobberers of the goal's
%   condition are listed once for all its establishers, and establishers
%   whose declobbering must fail are skipped (establish/5).

satisfy_op(Goal, Plan0, Plan) :-
    clobber_candidates(Goal, Plan0, Cands),
    establish(Goal, Cands, Plan0, Plan1, E),
    declobber(Goal, E, Cands, Plan1, Plan2),
    add_satisfied(Goal, E, Plan2, Plan).

add_satisfied(Goal, E, Plan0, Plan) :-
    plan_sat(Plan0, Sat),
    set_sat_of_plan([sat(Goal, E)|Sat], Plan0, Plan).

%!  satisfy_geo(+Goal, +Plan0, -Plan) is semidet.
%
%   Sec. 4.2: the operational conditions of geo(Id, A, Constraint, Conds)
%   are satisfied already (the operational stack is empty); find their
%   establishers and ask the CMS to add Constraint. Committed: the CMS's
%   answer is final, and a refusal fails the goal (the network of Plan0
%   stays in force).

satisfy_geo(Goal, Plan0, Plan) :-
    geo_step(Goal, Plan0, ok(Plan)).

%   geo_step(+Goal, +Plan0, -Result): ok(Plan) or refused(Vars), Vars the
%   network variables the refusal depends on (cms:cms_try/4).

geo_step(Goal, Plan0, Result) :-
    Goal = geo(_, A, Constraint, Conds),
    plan_sat(Plan0, Sat),
    maplist(establisher(Sat, A), Conds, Es),
    geo_objects(Constraint, Conds, Objects),
    plan_net(Plan0, Net0),
    cms_try(Constraint, Objects, Net0, Answer),
    (   Answer = ok(Net)
    ->  note(Plan0, "  CMS adds ~q~n", [Constraint]),
        set_net_of_plan(Net, Plan0, Plan1),
        add_satisfied(Goal, Es, Plan1, Plan),
        Result = ok(Plan)
    ;   Answer = refused(Reason, Vars),
        note(Plan0, "  CMS refuses ~q (~w: ~q)~n", [Constraint, Reason, Vars]),
        Result = refused(Vars)
    ).

%   establisher(+Sat, +A, +Cond, -E): E the establisher of the first
%   goal of Sat whose condition Cond holds before A, else `unknown` (a
%   plain recursion over the satisfied list, hundreds long at N = 50: no
%   redo of member/2 per entry).

establisher([], _, _, unknown).
establisher([Entry|Sat], A, Cond, E) :-
    (   Entry = sat(op(_, A1, C1), E0),
        A1 == A, C1 == Cond
    ->  E = E0
    ;   establisher(Sat, A, Cond, E)
    ).

%!  plan_partial(+Plan, -Partial) is det.
%
%   The partial plan of phase 1: partial(Actions, Order, Net, Satisfied),
%   the plan actions newest first, the ordering graph (ugraph), the CMS
%   network and the satisfied goals with their establishers,
%   sat(Goal, Establisher), followed by the separations posted,
%   sep(DeleteElement, Condition), oldest first (establish.pl).

plan_partial(Plan, partial(Actions, Order, Net, Satisfied)) :-
    plan_actions(Plan, Actions),
    plan_order(Plan, Ord),
    ordering_graph(Ord, Order),
    plan_net(Plan, Net),
    plan_sat(Plan, Sat),
    plan_seps(Plan, Seps0),
    reverse(Seps0, Seps),
    append(Sat, Seps, Satisfied).

                 /*******************************
                 *            TRACE             *
                 *******************************/

%   trace_step(+Goal, +Plan): the goal stacks and plan actions of Plan in
%   the layout of Figs. 21-22, then the goal about to be considered (the
%   first of its stack).

trace_step(Goal0, Plan) :-
    (   plan_trace(Plan, true)
    ->  plan_steps(Plan, K0),
        K is K0 + 1,
        plan_ops(Plan, Ops0),
        plan_geos(Plan, Geos0),
        plan_actions(Plan, Actions0),
        % a copy without dif/2 constraints (separations), which naming
        % the variables must not trip over
        copy_term([Ops0, Geos0, Actions0, Goal0], [Ops, Geos, Actions, Goal], _),
        \+ \+ ( name_variables([Ops, Geos, Actions, Goal]),
                format("~n--- step ~d~n", [K]),
                format("OPERATIONAL GOAL STACK~n"),
                forall(member(G, Ops), print_goal(G)),
                format("GEOMETRIC GOAL STACK~n"),
                forall(member(G, Geos), print_goal(G)),
                format("PLAN ACTIONS~n"),
                forall(member(A, Actions), print_action(A)),
                write_options(O),
                format("considering ~W~n", [Goal, O]) )
    ;   true
    ).

%!  print_goal(+Goal) is det.
%
%   Print a goal as Figs. 21-22 do: a geometric goal over several lines,
%   long label lists shortened to [first, second, ... last].

print_goal(op(Id, A, Cond)) :-
    write_options(O),
    format("  op(~q, ~q, ~W)~n", [Id, A, Cond, O]).
print_goal(geo(Id, A, C, Conds)) :-
    write_options(O),
    short_lists(C, C1),
    format("  geo(~q, ~q,~n      ~W", [Id, A, C1, O]),
    forall(member(X, Conds), format(",~n      ~W", [X, O])),
    format(")~n").

write_options([quoted(true), numbervars(true), spacing(next_argument)]).

%!  print_action(+Action) is det.
%
%   Print a plan action as Fig. 23: action(Id, Term).

print_action(action(Id, Term, _, _, _)) :-
    write_options(O),
    format("  action(~q, ~W)~n", [Id, Term, O]).

short_lists(T0, T) :-
    (   is_list(T0), length(T0, N), N > 4
    ->  T0 = [A, B|_], last(T0, Z),
        T = [A, B, '...', Z]
    ;   compound(T0)
    ->  T0 =.. [F|As0],
        maplist(short_lists, As0, As),
        T =.. [F|As]
    ;   T = T0
    ).

%   name_variables(+Terms): bind the unbound plan variables as the figures
%   name them: Grasp_N, Pos_N, else V_N.

name_variables(Terms) :-
    term_variables(Terms, Vs),
    foldl(name_variable(Terms), Vs, [], _).

name_variable(Terms, V, Counts0, Counts) :-
    (   subterm(S, Terms), compound(S),
        ( S = holding(_, W) ; S = reachable(W, _) ), W == V
    ->  Base = 'Grasp'
    ;   subterm(S, Terms), compound(S),
        S = part_location(_, W), W == V
    ->  Base = 'Pos'
    ;   Base = 'V'
    ),
    (   selectchk(Base-N0, Counts0, Rest) -> true ; N0 = 0, Rest = Counts0 ),
    N is N0 + 1,
    Counts = [Base-N|Rest],
    format(atom(Name), "~w_~d", [Base, N]),
    V = '$VAR'(Name).

%   subterm(?Sub, +Term): Sub is Term or a subterm of it, Term first, then
%   its arguments left to right (library(occurs)'s sub_term/2, which a
%   cold start would compile from source only for the trace).

subterm(X, X).
subterm(X, Term) :-
    compound(Term),
    arg(_, Term, Arg),
    subterm(X, Arg).
