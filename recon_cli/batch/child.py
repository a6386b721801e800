"""The process of one batch job: ``recon <command> ...`` that ends with the batch.

``python -m recon_cli.batch.child <pid> <module> <command> <args...>`` asks the kernel to
send it SIGTERM when the thread that started it ends (Linux ``PR_SET_PDEATHSIG``), checks
that ``pid`` (the batch) is still its parent, then runs ``<module>`` as ``python -m`` would
(recon's entry module, :data:`recon_cli.batch.spec.ENTRY_MODULE`) with the arguments. So a batch
that is killed (SIGKILL, a lost Dask worker) leaves no job behind writing into a folder
that ``recon batch --resume`` is about to clear; SIGTERM lets recon stop as on Ctrl-C.
(``preexec_fn`` would do the same in the forked child, but is unsafe with threads.)
"""

from __future__ import annotations

import ctypes
import os
import runpy
import signal
import sys


def _die_with_parent() -> None:
    if not sys.platform.startswith("linux"):
        return
    try:

        libc = ctypes.CDLL(None, use_errno=True)
        PR_SET_PDEATHSIG = 1
        libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    except (OSError, AttributeError):  # no prctl: the job just runs on
        pass


def main() -> None:
    parent = int(sys.argv[1])
    _die_with_parent()
    if os.getppid() != parent:  # the batch died before the request was in place
        sys.exit(128 + int(signal.SIGTERM))
    module = sys.argv[2]
    sys.argv = [module, *sys.argv[3:]]
    runpy.run_module(module, run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main()
