/*  spar-py: the planner's default options, written once.

    Every default of the planner's options lives in default_option/2 below;
    the Prolog code reads it (option/3 with the default from here) and the
    Python side reads all of them in one query of default_options/1, so a
    default is changed in one place.

      max_actions    auto     the largest plan phase 1 tries (Sec. 2): auto
                              derives it from the problem, as
                              derived_max_actions/2 says
      max_actions_floor 12    the least bound auto gives
      max_steps      auto     goal steps over all rounds of phase 1; 0: none;
                              auto derives it from the problem, as
                              derived_max_steps/2 says
      max_steps_floor 10000   the least budget auto gives
      declobber      [promotion, separation, white_knight]
                              declobbering methods in the order tried
                              (Sec. 4.1; [promotion, white_knight] is the
                              paper's planner)
      forward_check  true     check a geometric goal with the CMS as soon as
                              its variables are bound
      trace          false    print the goal stacks at each step
      max_instances  50       plan instances examined at most in phase 2
*/
:- module(spar_defaults,
          [ default_option/2,        % ?Name, ?Value
            default_options/1,       % -Dict
            derived_max_actions/2,   % +LowerBound, -Bound
            derived_max_steps/2      % +LowerBound, -Steps
          ]).
:- use_module(library(error)).

%!  default_option(?Name, ?Value) is nondet.
%
%   Value is the default of the planner option Name (see the module
%   header). With Name bound it is semidet.
%
%   ==
%   ?- default_option(max_instances, N).
%   N = 50.
%   ==

default_option(max_actions, auto).
default_option(max_actions_floor, 12).
default_option(max_steps, auto).
default_option(max_steps_floor, 10000).
default_option(declobber, [promotion, separation, white_knight]).
default_option(forward_check, true).
default_option(trace, false).
default_option(max_instances, 50).

%!  default_options(-Dict) is det.
%
%   Dict maps every option name of default_option/2 to its default, for
%   the Python side to read once. The booleans are written @(true) and
%   @(false), so that janus gives Python a dict of ints, bools and a list
%   of str: {"max_actions": "auto", "forward_check": True, ...}.
%
%   ==
%   ?- default_options(D), get_dict(max_instances, D, N).
%   N = 50.
%   ==

default_options(Dict) :-
    findall(Name-Value, ( default_option(Name, V), janus_value(V, Value) ),
            Pairs),
    dict_pairs(Dict, _, Pairs).

janus_value(true, @(true)) :- !.
janus_value(false, @(false)) :- !.
janus_value(V, V).

%!  derived_max_actions(+LowerBound, -Bound) is det.
%
%   The bound on the plan size that max_actions(auto) gives a problem
%   whose plans need at least LowerBound actions (goals:lower_bound/2,
%   admissible): twice that, so that every action counted may need one
%   more (a regrasp: a put-down and a pickup for every two), and at least
%   max_actions_floor. The step budget (max_steps) and the caller's
%   timeout are what limit the search in practice; the bound keeps its
%   rounds of iterative deepening finite.
%
%   ==
%   ?- derived_max_actions(4, B).
%   B = 12.
%   ?- derived_max_actions(200, B).
%   B = 400.
%   ==
%
%   @error type_error(nonneg, LowerBound) if LowerBound is not a
%          non-negative integer.

derived_max_actions(LB, Bound) :-
    must_be(nonneg, LB),
    default_option(max_actions_floor, Floor),
    Bound is max(Floor, 2 * LB).

%!  derived_max_steps(+LowerBound, -Steps) is det.
%
%   The step budget that max_steps(auto) gives a problem whose plans need
%   at least LowerBound actions: 100 goal steps for each of them (a plan
%   found without backtracking takes about 4 per action: the action's
%   operational and geometric goals), and at least max_steps_floor, so
%   that the budget stops a hopeless search of a small problem as soon as
%   before and lets a large solvable one finish.
%
%   ==
%   ?- derived_max_steps(4, S).
%   S = 10000.
%   ?- derived_max_steps(400, S).
%   S = 40000.
%   ==
%
%   @error type_error(nonneg, LowerBound) if LowerBound is not a
%          non-negative integer.

derived_max_steps(LB, Steps) :-
    must_be(nonneg, LB),
    default_option(max_steps_floor, Floor),
    Steps is max(Floor, 100 * LB).
