/*  Tests of declobbering by separation (establish.pl, Sec. 4.1; Chapman's
    separation, Sec. 7.1) on the separation cell (fixtures/
    separation_cell.pl): a peg at init_pos1 and at init_pos5, the goals
    part_location(peg, init_pos1) and holding(peg, _), whose only plan
    within the bound keeps the pickup's part_location(peg, Pos) apart from
    the first goal.

    swipl -g run_tests -t halt tests/prolog/separation.plt
*/
:- use_module('../../prolog/spar').
:- use_module('../../prolog/goals').
:- use_module('../../prolog/plan_state', except([plan_actions/2])).  % spar's toplevel has its own
:- use_module('../../prolog/establish').
:- use_module(fixtures/separation_cell).
:- use_module(library(plunit)).
:- use_module(library(apply)).
:- use_module(library(lists)).

:- begin_tests(separation, [setup(load_separation_cell)]).

options(Methods, [ max_actions(4), declobber(Methods),
                   oracle(fixture_separation_cell:all_pairs_oracle) ]).

phase1_with(Methods, Outcome) :-
    options(Methods, Options),
    phase1(peg_in_block, Options, Outcome).

goal1(op(top_1, finish, part_location(peg, init_pos1))).

%   plan_with_pickup(-Plan, -Pos): the null plan with goal 1 established by
%   the initial state, then pickup(peg, grasp_1) added, its
%   part_location(peg, Pos) precondition not yet established.

plan_with_pickup(Methods, Plan, Pos) :-
    options(Methods, Options),
    initial_plan(4, Options, P0),
    goal1(G1),
    once(establish(G1, P0, P1, start)),
    once(new_action(holding(peg, _), Id, [Id-finish], P1, Plan)),
    plan_state:plan_actions(Plan, Actions),
    memberchk(action(Id, _, _, _, dellist(Dels)), Actions),
    memberchk(part_location(peg, Pos), Dels).

test(known_method) :-
    known_declobber_method(separation).

test(default_order, Ms == [promotion, separation, white_knight]) :-
    initial_plan(4, [], P),
    plan_methods(P, Ms).

test(posts_dif, [Seps == [sep(part_location(peg, Pos), part_location(peg, init_pos1))]]) :-
    plan_with_pickup([separation], P0, Pos),
    goal1(G1),
    once(declobber(G1, start, P0, P)),
    plan_seps(P, Seps),
    var(Pos),
    \+ Pos = init_pos1,                     % the dif/2 is in force
    Pos = init_pos5.

test(promotion_cannot) :-                   % a cycle through finish
    plan_with_pickup([promotion], P0, _),
    goal1(G1),
    \+ declobber(G1, start, P0, _).

test(undone_on_backtracking, [Pos-Seps == init_pos1-[]]) :-
    plan_with_pickup([separation], P0, Pos),
    goal1(G1),
    \+ ( declobber(G1, start, P0, P), plan_seps(P, [_]), fail ),
    term_attvars(P0, []),                   % no stale dif/2 left
    Pos = init_pos1,
    plan_seps(P0, Seps).

test(phase1_plan_shows_separation,
     [ Terms-Sat == [pickup(peg, grasp_1)]-
                    [sep(part_location(peg, init_pos5), part_location(peg, init_pos1))] ]) :-
    phase1_with([promotion, separation, white_knight], plan(P)),
    partial_actions(P, As),
    maplist([action(_, T), T]>>true, As, Terms),
    P = partial(_, _, _, Sat0),
    include([S]>>(S = sep(_, _)), Sat0, Sat).

test(default_options_separate, [Terms == [pickup(peg, grasp_1)]]) :-
    phase1(peg_in_block, [max_actions(4),
                          oracle(fixture_separation_cell:all_pairs_oracle)],
           plan(P)),
    partial_actions(P, As),
    maplist([action(_, T), T]>>true, As, Terms).

test(partial_dict_separations,
     [ Texts-Deleted == [["part_location(peg,init_pos5)", "part_location(peg,init_pos1)"]]-
                        [args-["peg", "init_pos5"], functor-"part_location"] ]) :-
    phase1_with([promotion, separation, white_knight], plan(P)),
    partial_dict(P, D),
    [Sep] = D.separations,
    Texts = [Sep.text],
    dict_pairs(Sep.deleted, _, Deleted).

test(print_partial_section) :-
    phase1_with([promotion, separation, white_knight], plan(P)),
    with_output_to(string(S), print_partial(P)),
    once(sub_string(S, _, _, _, "SEPARATIONS\n  dif(part_location(peg, init_pos5), part_location(peg, init_pos1))")).

test(no_separation_section_without, [cleanup(load_separation_cell)]) :-
    load_cell_paper,
    phase1(peg_in_block, [oracle(fixture_paper_cell:table_oracle(hole_down))],
           plan(P)),
    partial_dict(P, D),
    D.separations == [],
    with_output_to(string(S), print_partial(P)),
    \+ sub_string(S, _, _, _, "SEPARATIONS").

test(instances_respect_separation,
     [ Bindings == [grasp_1=p1G1, init_pos1=tr1, init_pos5=tr5] ]) :-
    phase1_with([promotion, separation, white_knight], plan(P)),
    once(partial_instances(P, instance(_, Bindings))).

test(instance_violating_separation_skipped,
     [ cleanup(load_separation_cell) ]) :-
    load_separation_cell(tr1),                % init_pos5 gets init_pos1's label
    phase1_with([promotion, separation, white_knight], plan(P)),
    P = partial(_, _, _, Sat),
    memberchk(sep(_, _), Sat),
    \+ partial_instances(P, _).

test(trace_shows_separation) :-
    options([promotion, separation, white_knight], Options),
    with_output_to(string(S),
                   phase1(peg_in_block, [trace(true)|Options], plan(_))),
    once(sub_string(S, _, _, _, "may clobber part_location(peg,init_pos1): separation")).

test(paper_planner_no_plan, [Outcome = no_plan(4, _)]) :-
    phase1_with([promotion, white_knight], Outcome).

:- end_tests(separation).

load_cell_paper :-
    fixture_paper_cell:load_cell(hole_down).
