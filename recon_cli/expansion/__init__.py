"""Expanding a user's xacro file under checks: an automation script or a cell's robot
description. What the expansion may read (:mod:`.readable`), the checked and bounded
expression evaluator (:mod:`.expressions`), xacro patched to use it (:mod:`.sandbox`), and
the files checked and tagged with their sources before xacro sees them (:mod:`.annotate`)."""
