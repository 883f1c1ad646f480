"""The gap diagnosis runs with every BLAS pool at one thread: its parallelism is its worker
threads, and OpenBLAS's own threads beside them made the linear simulations 2.7x slower
(``benchmarks/run.py``, case ``blas_threads``)."""

from threadpoolctl import threadpool_info, threadpool_limits

from vibroscope.gap import diagnosis


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_the_whole_diagnosis_runs_on_one_blas_thread_and_restores_the_pools(monkeypatch):
    seen = {}

    def fake(*args, **kwargs):
        seen["threads"] = _blas_threads()
        return "report"

    monkeypatch.setattr(diagnosis, "_diagnose", fake)
    with threadpool_limits(2, user_api="blas"):
        before = _blas_threads()
        assert before and max(before) == 2
        assert diagnosis.diagnose(None, None) == "report"
        assert _blas_threads() == before  # restored after the call
    assert seen["threads"] and set(seen["threads"]) == {1}
