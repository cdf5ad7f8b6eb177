/*  spar-py: the file search path spar, the checkout the planner lies in.

    user:file_search_path(spar, Root), Root the directory above prolog/:
    spar(kb/templates/spar_actions) names the action templates wherever
    the checkout is and whichever file asks. The modules of prolog/ that
    load a template load this file first.

    The path is a clause of this file, made when the file is compiled
    (term_expansion/2 below): reloading the file (collect_docs/0) replaces
    it instead of adding another, and a .qlf image (spar_py.planning.qlf)
    holds the checkout it was compiled from, which is the one loading it
    (images are keyed by their files' absolute paths).
*/
:- module(spar_paths, []).

:- multifile user:file_search_path/2.
:- dynamic user:file_search_path/2.

term_expansion(spar_root, user:file_search_path(spar, Root)) :-
    prolog_load_context(directory, Dir),
    file_directory_name(Dir, Root).

spar_root.
