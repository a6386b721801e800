"""The seed of a run and Open3D's random draws.

:data:`DEFAULT_SEED` and :data:`SEED_RANGE` are the seed of every random number generator of a
run (``Config.seed``: --seed, a script's run, a batch job). Open3D's random draws (surface
sampling, RANSAC) come from one global generator that no Open3D call takes as an argument;
:func:`open3d_draws` is the one place that seeds it, with the seed its caller passes in, right
before the draws it governs, so that a result depends on that seed only and not on what ran
before in the process."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

#: the seed of a run unless one is given, and the seeds there are (numpy takes 0 ... 2^32-1)
DEFAULT_SEED = 0
SEED_RANGE = (0, 2**32 - 1)


@contextmanager
def open3d_draws(seed: int, *, single_thread: bool = False) -> Iterator[None]:
    """Open3D's generator seeded with ``seed`` for the calls inside. ``single_thread``: run
    them on one thread (Open3D's RANSAC draws from several threads in whatever order they
    run; with one thread the seed fixes its samples)."""
    import open3d as o3d

    threads = o3d.utility.get_max_threads()
    if single_thread:
        o3d.utility.set_max_threads(1)
    try:
        o3d.utility.random.seed(seed)
        yield
    finally:
        if single_thread:
            o3d.utility.set_max_threads(threads)
