"""``in_order``: the items of many producers in the plain loop's order, made in threads a bounded
distance ahead, a producer's exception raised to the consumer."""

import threading

import numpy as np
import pytest

from diegocal.parallel import in_order


def _producers(n_blocks: int, per_block: int, made: list, lock: threading.Lock):
    def producer(k):
        def gen():
            rng = np.random.default_rng(k)
            for i in range(per_block):
                with lock:
                    made.append((k, i))
                yield k, i, rng.normal(size=3)

        return gen

    return [producer(k) for k in range(n_blocks)]


def test_items_come_in_the_plain_loops_order_whatever_the_threads():
    lock = threading.Lock()
    plain = list(in_order(_producers(7, 5, [], lock), jobs=1))
    threaded = list(in_order(_producers(7, 5, [], lock), jobs=3))
    assert [(k, i) for k, i, _ in threaded] == [(k, i) for k, i, _ in plain] == [
        (k, i) for k in range(7) for i in range(5)
    ]
    for a, b in zip(plain, threaded, strict=True):
        np.testing.assert_array_equal(a[2], b[2])


def test_producers_run_at_most_a_few_items_ahead_of_the_consumer():
    lock, made = threading.Lock(), []
    items = in_order(_producers(6, 10, made, lock), jobs=2, depth=2)
    first = next(items)
    assert first[:2] == (0, 0)
    threading.Event().wait(0.3)  # let the threads run as far as they may
    with lock:
        ahead = len(made)
    # block 0: the item read + 2 queued + 1 waiting to be put; block 1 the same, not yet read
    assert ahead <= 2 * (2 + 2)
    rest = list(items)
    assert len(rest) == 59


def test_a_producers_exception_reaches_the_consumer():
    def good():
        yield from range(3)

    def bad():
        yield 10
        raise ValueError("block 1 failed")

    got = []
    with pytest.raises(ValueError, match="block 1 failed"):
        for x in in_order([good, bad, good], jobs=2):
            got.append(x)
    assert got == [0, 1, 2, 10]


def test_a_consumer_that_stops_leaves_the_producers_not_yet_started_unmade():
    lock, made = threading.Lock(), []
    items = in_order(_producers(40, 3, made, lock), jobs=2)
    with pytest.raises(RuntimeError):
        for k, i, _ in items:
            if (k, i) == (1, 0):
                raise RuntimeError("the consumer fails")
    items.close()  # as the garbage collector would: the threads are told to stop and joined
    with lock:
        blocks = {k for k, _ in made}
    assert len(blocks) <= 6  # a few producers ahead at most, not all 40


def test_producers_in_threads_use_one_blas_thread_each():
    """BLAS's own threads under several producers oversubscribe the cores, and its reductions then
    split differently from run to run: a diagnosis with --jobs 2 was not reproducible."""
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas_threads():
        return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]

    def producer():
        yield blas_threads()

    with threadpool_limits(limits=2, user_api="blas"):  # the suite runs with one (conftest)
        assert set(blas_threads()) == {2}
        seen = list(in_order([producer, producer, producer], jobs=2))
        assert set(blas_threads()) == {2}  # the caller's limit back after the loop
    assert len(seen) == 3 and all(set(n) == {1} for n in seen)
