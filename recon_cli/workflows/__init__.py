"""Workflows: what a command does from start to end, orchestrating the library.

capture      planned moves through given views, a scan at each
autoscan     the non-model-based view planner (thesis Table 2.1) around an unknown object
script_run   an automation script's commands, in order (run loop; handlers in scripts/)

Each opens its acquisition session with :func:`recon_cli.session.open_session` and only
orchestrates: planning, view planning, registration and the backends live elsewhere.
"""
