/*  spar-py: the planner's entry points (phases 1 and 2 of Sec. 2) and the
    terms they return.

    Load this file; it loads the rest (Fig. 1, one module per box), listed
    so that each uses only modules below it (no cycle:
    tests/prolog/modules.plt):

      spar_toplevel.pl the toplevel: load_problem/1,2, print_plan/1, help
      uncertainty.pl  phase 2: plan instances run, sensing and recovery
                    inserted (Secs. 3.3, 4.3)
      partial_plan.pl the partial plan: readers, instances, dict, printing
      goals.pl      goal stacks, satisfied list, the loop, geometric goals
      establish.pl  establishment, clobbering, promotion, white knights
      plan_state.pl the plan record the loop threads, the search recorder
      spar_defaults.pl  the default of every planner option
      ordering.pl   the ordering graph: prior_to/2, cycles, linearisations
      cms.pl        the geometric constraint network
      csp.pl        network consistency (Figs. 16-17), AC-3, solutions
      foreign.pl    the calls into Python
      ../kb/templates/spar_actions.pl   templates and rules (Figs. 2-6)
      ../kb/templates/spar_sensing.pl   Figs. 11-13, for phase 2
      kb.pl         the knowledge base (module kb), loaded from Python
      spar_paths.pl the file search path spar (the checkout): the
                    templates are loaded as spar(kb/templates/...)

    spar reexports partial_plan.pl and spar_toplevel.pl: a user of the
    planner finds every entry point here.

    Terms:

      Outcome  = plan(Partial) | no_plan(MaxActions, UnmetGoal)
      Partial  = partial(Actions, Order, Net, Satisfied)
                   Actions    instantiated templates, newest first (Fig. 23):
                              action(Id, Term, preconditions(Ops, Geos),
                                     addlist(Adds), dellist(Dels))
                   Order      the ordering graph (a ugraph over action ids)
                   Net        the CMS network (cms.pl)
                   Satisfied  sat(Goal, Establisher) for every goal met,
                              then sep(D, Cond) for every separation
                              (establish.pl): D, a delete-list element of
                              a possible clobberer, is kept apart from
                              Cond, in the plan and in every instance
      Instance = instance(Steps, Bindings)
                   Steps      the actions in an execution order, every plan
                              variable replaced by its label
                   Bindings   Var = Label for every network variable
      Goals    = op(Id, ActionId, Cond) | geo(Id, ActionId, Constraint, Conds)
*/
:- module(spar,
          [ plan/2,                  % +Problem, -Plan
            plan/3,                  % +Problem, +Options, -Plan
            plan_dict/4,             % +Problem, +Options, -Dict, -Text
            plan_phase1/2,           % +Problem, -Partial
            phase1/3                 % +Problem, +Options, -Outcome
          ]).
:- use_module(library(error)).
:- use_module(library(lists)).
:- use_module(library(apply)).
:- use_module(library(option)).
:- use_module(library(yall)).
:- use_module(library(time)).
:- use_module(kb, [with_problem/2]).
:- use_module(foreign, [term_data/2]).
:- use_module(establish, [known_declobber_method/1]).
:- use_module(goals, [phase1_search/3, max_action_bound/2]).
:- use_module(spar_defaults, [default_option/2]).
:- use_module(spar_paths, []).    % the file search path spar
:- use_module(spar(kb/templates/spar_actions), []).
:- use_module(spar(kb/templates/spar_sensing), []).
:- use_module(uncertainty, [phase2/4, print_ur/1, ur_dict/2]).
%   What a user of the planner calls besides the entry points above: the
%   partial plan's readers, instances, dict and printing (partial_plan.pl),
%   print_plan/1, load_problem/1,2 and the rest of the toplevel
%   (spar_toplevel.pl).
:- reexport(partial_plan).
:- reexport(spar_toplevel).

:- meta_predicate phase1(+, :, -).

%!  plan_phase1(+Problem, -Partial) is semidet.
%
%   Phase 1 with the default options: Partial satisfies every operational
%   and geometric goal of the loaded problem Problem (kb:problem/1). Fails
%   if there is no plan of at most 12 actions.
%
%   @error existence_error(problem, Problem) if Problem is not loaded.

plan_phase1(Problem, Partial) :-
    phase1(Problem, [], Outcome),
    Outcome = plan(Partial).

%!  phase1(+Problem, +Options, -Outcome) is det.
%
%   Run phase 1 on the loaded problem Problem. Outcome is plan(Partial) or
%   no_plan(MaxActions, UnmetGoal): no plan of at most MaxActions actions,
%   UnmetGoal the goal that failed at the deepest step of the search with
%   that bound: the deepest geometric goal the CMS refused if there is
%   one, else the deepest operational goal. MaxActions is max_actions
%   unless the step budget ran out first; it is then the largest bound
%   searched completely. Options:
%
%     - max_actions(N)   the largest plan tried, or auto (the default:
%                        derived from the problem's lower bound on the
%                        plan size, spar_defaults:derived_max_actions/2);
%                        the bound rises from that lower bound to N
%     - trace(Bool)      print the goal stacks and plan actions at each
%                        step (Figs. 21-22) to current output (false)
%     - declobber(Ms)    the declobbering methods, in the order tried
%                        (default [promotion, separation, white_knight];
%                        [promotion, white_knight] is the paper's planner)
%     - forward_check(B) check a geometric goal with the CMS as soon as its
%                        variables are bound, not only at its turn (true);
%                        the same plan, found sooner; false gives the
%                        paper's order of events in the trace (Sec. 6)
%     - max_steps(N)     a budget of goal steps over all rounds (auto:
%                        100 per action of the lower bound, at least 10000; 0
%                        for none); phase-1 planning is exponential in the
%                        plan size and undecidable (Secs. 2, 7.2)
%     - placements(Rule) how a put-down into a stable pose (no X, Y)
%                        counts as reachable: reachable (some placement
%                        in the cell's free table regions reaches it, the
%                        default) or paper (Sec. 5.2.4: assumed)
%     - oracle(Closure)  compute arc pairs with call(Closure, Constraint,
%                        Objects, Gs, Ps, Pairs) instead of
%                        foreign:arc_pairs/5; a test double for Prolog-only
%                        tests
%
%   ==
%   ?- phase1(peg_in_block, [max_actions(6)], plan(P)), print_partial(P).
%   ==
%
%   @error existence_error(problem, Problem) if Problem is not loaded.
%   @error type_error(nonneg, N), type_error(boolean, B),
%          domain_error(declobber_method, M) for bad options.

phase1(Problem, M:Options0, Outcome) :-
    must_be(atom, Problem),
    must_be(list, Options0),
    maplist(check_option(M), Options0, Options1),
    run_options(Problem, Options1, Options),
    with_problem(Problem, phase1_search(Options, Outcome, _)).

%   run_options(+Problem, +Options0, -Options): the arcs of Problem's
%   network come from the Python kinematics of that problem, told which
%   problem and which placement rule (foreign:arc_pairs/7), unless a test
%   gives its own oracle.
run_options(Problem, Options0, Options) :-
    (   option(oracle(_), Options0)
    ->  Options = Options0
    ;   option(placements(Rule), Options0, reachable),
        Options = [oracle(foreign:arc_pairs(Problem, Rule))|Options0]
    ).

check_option(_, max_actions(N), max_actions(N)) :- !,
    (   N == auto
    ->  true
    ;   must_be(nonneg, N)
    ).
check_option(_, max_steps(N), max_steps(N)) :- !,
    (   N == auto
    ->  true
    ;   must_be(nonneg, N)
    ).
check_option(_, forward_check(B), forward_check(B)) :- !,
    must_be(boolean, B).
check_option(_, trace(B), trace(B)) :- !,
    must_be(boolean, B).
check_option(_, declobber(Ms), declobber(Ms)) :- !,
    must_be(list(atom), Ms),
    forall(member(X, Ms),
           (   known_declobber_method(X)
           ->  true
           ;   domain_error(declobber_method, X)
           )).
check_option(_, placements(R), placements(R)) :- !,
    must_be(oneof([reachable, paper]), R).
check_option(M, oracle(O0), oracle(O)) :- !,
    must_be(callable, O0),
    strip_module(M:O0, Mod, O1),
    O = Mod:O1.
check_option(_, Option, Option).

		 /*******************************
		 *     BOTH PHASES (Sec. 2)     *
		 *******************************/

%!  plan(+Problem, -Plan) is semidet.
%!  plan(+Problem, +Options, -Plan) is semidet.
%
%   Plan the loaded problem Problem in both phases: Plan is
%   plan(Partial, Result), Partial the phase-1 partial plan (phase1/3),
%   Result the phase-2 outcome (uncertainty:phase2/3). Fails if phase 1
%   finds no plan. Options are phase1/3's plus max_instances(Cap).
%
%   ==
%   ?- plan(peg_in_block, P), print_plan(P).
%   ==
%
%   @error existence_error(problem, Problem) if Problem is not loaded.

plan(Problem, Plan) :-
    plan(Problem, [], Plan).

plan(Problem, Options, plan(Partial, Result)) :-
    must_be(list, Options),
    partition(phase2_option, Options, P2, P1),
    with_problem(Problem,
                 once(( phase1(Problem, P1, Outcome),   % semidet: the first plan, no choice point
                        Outcome = plan(Partial),
                        phase2(Problem, Partial, P2, Result) ))).

phase2_option(max_instances(_)).

%!  plan_dict(+Problem, +Options:dict, -Dict, -Text) is det.
%
%   The bridge's entry point: plan Problem with Options (a dict with keys
%   max_actions, max_instances, separation, placements ("reachable" or
%   "paper"), phase1_only, trace, timeout; timeout 0 means none) and return the outcome as a dict for the JSON
%   schema (docs/json-schema.md) and Text, what print_plan/1 and the trace
%   print.
%
%   @error time_limit_exceeded if the timeout passes.

plan_dict(Problem, Opts, Dict, Text) :-
    must_be(atom, Problem),
    must_be(dict, Opts),
    phase1_options(Opts, P1),
    Run = with_problem(Problem, plan_dict_(Problem, Opts, P1, Dict)),
    (   Opts.timeout > 0
    ->  call_with_time_limit(Opts.timeout, with_output_to(string(Text), Run))
    ;   with_output_to(string(Text), Run)
    ).

phase1_options(Opts, [max_actions(Max), trace(Trace), declobber(Ms),
                      placements(Rule)]) :-
    (   string(Opts.max_actions) -> atom_string(Max, Opts.max_actions) ; Max = Opts.max_actions ),
    (   Opts.trace == @(true) -> Trace = true ; Trace = false ),
    atom_string(Rule, Opts.placements),
    (   Opts.separation == @(true), known_declobber_method(separation)
    ->  default_option(declobber, Ms)
    ;   Ms = [promotion, white_knight]
    ).

plan_dict_(Problem, Opts, P1, Dict) :-
    statistics(cputime, T0),
    phase1(Problem, P1, Outcome),
    statistics(cputime, T1),
    Phase1 is T1 - T0,
    (   Outcome = no_plan(N, Goal)
    ->  format(string(G), "~q", [Goal]),
        max_action_bound(P1, Max),
        (   Opts.trace \== @(true)      % the user's line is the caller's (reason.summary)
        ->  true
        ;   N < Max                     % the step budget ran out first
        ->  format("NO PLAN within ~w actions (the last bound searched completely \c
                    before the step budget ran out; the bound was ~w): the goal \c
                    that could not be met: ~s~n", [N, Max, G])
        ;   format("NO PLAN within ~w actions (the bound on the plan size; \c
                    --max-actions raises it): the goal that could not be met: ~s~n", [N, G])
        ),
        term_data(Goal, GD),
        Dict = _{outcome: "no_plan", reason: _{max_actions: N, bound: Max, goal: G, goal_data: GD},
                 partial: @(none), instance: @(none), timing: _{phase1_s: Phase1}}
    ;   Outcome = plan(Partial),
        partial_dict(Partial, PD),
        print_partial(Partial),
        (   Opts.phase1_only == @(true)
        ->  Dict = _{outcome: "plan", reason: @(none), partial: PD, instance: @(none),
                     timing: _{phase1_s: Phase1}}
        ;   phase2(Problem, Partial, [max_instances(Opts.max_instances)], R),
            statistics(cputime, T2),
            Phase2 is T2 - T1,
            print_ur(R),
            ur_dict(R, ID),
            phase2_outcome(R, ID, Out, Reason),
            Dict = _{outcome: Out, reason: Reason, partial: PD, instance: ID,
                     timing: _{phase1_s: Phase1, phase2_s: Phase2}}
        )
    ).

%   phase2_outcome(+Result, +InstanceDict, -Outcome, -Reason): a partial
%   plan none of whose instances examined can be executed at all (a
%   put-down with no reachable placement, a step with no joint solution)
%   is no plan; phase 2 says why, with the cap on the instances and
%   whether the partial plan has no further instance.

phase2_outcome(no_instance(N, Cap, _), ID, "no_plan",
               _{phase: 2, instances_examined: N, instance_cap: Cap, complete: C, why: Why}) :-
    !,
    get_dict(reason, ID, Why),
    get_dict(complete, ID, C).
phase2_outcome(_, _, "plan", @(none)).
