"""Threads: BLAS and OpenMP on one thread per worker, independent work over ``jobs`` workers.

Why one BLAS thread: diegocal's heavy steps are many small or medium factorisations and products
(a likelihood per joint, a least-squares problem per candidate), where OpenBLAS's own threads only
contend, and contend badly on a shared machine: an ``sgp-fit`` of 4,000 samples took 213 s wall
with the default threads on two cores beside one other job, and 30 s with one thread; a 60-s UR5
diagnosis 17.8 s against 6.6 s. So the library runs its heavy calls under :func:`one_blas_thread`
and spreads *independent* units (per joint, per hyperparameter start, per cross-validation fold,
per candidate) over ``jobs`` Python threads with :func:`thread_map`: LAPACK and numpy's BLAS
release the GIL, so the threads run in parallel, each on one BLAS thread, and ``--jobs 1`` (the
default) uses one core whatever the machine has.
"""

from __future__ import annotations

import functools
import queue
import threading
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor

from threadpoolctl import ThreadpoolController

_CONTROLLER = None


def _controller():
    """One threadpoolctl controller per process (listing the loaded libraries is the slow part)."""
    global _CONTROLLER
    if _CONTROLLER is None:
        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER


def one_blas_thread():
    """Context manager: BLAS and OpenMP thread pools limited to one thread inside it (nested uses
    are fine; the previous limits come back on exit)."""
    return _controller().limit(limits=1)


def single_threaded(fn: Callable) -> Callable:
    """Decorator: run ``fn`` under :func:`one_blas_thread`."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with one_blas_thread():
            return fn(*args, **kwargs)

    return wrapper


def thread_map(fn: Callable, items: Iterable, jobs: int = 1) -> list:
    """``[fn(x) for x in items]``, in ``jobs`` threads when jobs > 1 (order kept; the first
    exception is re-raised). Use it for independent units whose work is in numpy/LAPACK."""
    items = list(items)
    if jobs <= 1 or len(items) <= 1:
        return [fn(x) for x in items]
    with ThreadPoolExecutor(max_workers=min(int(jobs), len(items))) as pool:
        return list(pool.map(fn, items))


def thread_imap(fn: Callable, items: Iterable, jobs: int = 1):
    """:func:`thread_map` as a generator: each result in order as soon as it (and those before it)
    is done, so that the caller can report progress while the rest run."""
    items = list(items)
    if jobs <= 1 or len(items) <= 1:
        yield from (fn(x) for x in items)
        return
    with ThreadPoolExecutor(max_workers=min(int(jobs), len(items))) as pool:
        yield from pool.map(fn, items)


def in_order(producers: list, jobs: int = 1, depth: int = 2):
    """The items of each generator function of ``producers`` in turn (all of the first's, then the
    second's, ...), made in ``jobs`` threads when jobs > 1: while the caller consumes one
    producer's items, the next producers already make theirs, each at most ``depth`` ahead, so
    that what is alive stays a few items per thread whatever the number of producers. The items
    and their order are those of the plain loop; a producer's exception is re-raised here."""
    if jobs <= 1 or len(producers) <= 1:
        for make in producers:
            yield from make()
        return
    queues = [queue.Queue(maxsize=depth) for _ in producers]
    stop = threading.Event()
    done = object()

    def put(k: int, item) -> bool:
        while not stop.is_set():
            try:
                queues[k].put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def work(k: int) -> None:
        if stop.is_set():  # the consumer has stopped: the producers not yet started make nothing
            return
        try:
            for item in producers[k]():
                if not put(k, (None, item)):
                    return
            put(k, (done, None))
        except BaseException as exc:  # handed to the consumer, raised there
            put(k, (exc, None))

    # one BLAS thread each: BLAS's own threads on top of these oversubscribe the cores, and with
    # several callers at once its reductions split differently from run to run (not reproducible)
    with one_blas_thread(), ThreadPoolExecutor(max_workers=min(int(jobs), len(producers))) as pool:
        for k in range(len(producers)):
            pool.submit(work, k)
        try:
            for q in queues:
                while True:
                    flag, item = q.get()
                    if flag is done:
                        break
                    if flag is not None:
                        raise flag
                    yield item
        finally:
            stop.set()  # producers still running give up at their next item
