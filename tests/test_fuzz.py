"""A bounded run of the deep-EXR fuzz harness (tests/fuzz_exr.py) on every test run: mutated real and generated
deep files must read, or fail with one RanadError line, within the harness's CPU and memory limits.

The long run (10^5 cases) is a documented command in the README: ``python tests/fuzz_exr.py --cases 100000``.
"""

from __future__ import annotations

import json
import os

import fuzz_exr

CASES = int(os.environ.get("RANAD_FUZZ_CASES", "300"))
SEED = int(os.environ.get("RANAD_FUZZ_SEED", "26"))


def test_mutation_is_deterministic_and_varied(tmp_path):
    corpus = fuzz_exr.load_corpus(str(tmp_path))
    names = {os.path.basename(c[0]) for c in corpus}
    assert {"gen_none.exr", "gen_zips.exr", "gen_rle.exr", "gen_tiled.exr", "gen_multipart.exr"} <= names
    assert any(not n.startswith("gen_") for n in names)  # at least one real file
    a = [fuzz_exr.make_case(corpus, 5, k) for k in range(40)]
    assert a == [fuzz_exr.make_case(corpus, 5, k) for k in range(40)]
    assert len({data for data, _, _ in a}) == 40
    kinds = {step.split("@")[0].split(":")[0].rstrip("0123456789") for _, _, what in a for step in what.split()}
    assert {"truncate", "flip", "extreme"} <= kinds


def test_fuzz_bounded_run():
    summary = fuzz_exr.campaign(CASES, SEED, cpu_limit=5.0, mem_limit_mb=512, oiio_every=25)
    failures = summary.pop("failures")
    assert summary["cases"] == CASES
    assert summary["read"] > 0 and summary["refused"] > 0, summary  # both outcomes exercised
    assert not failures, "\n".join(json.dumps(f) for f in failures[:20]) + "\n" + json.dumps(summary) + (
        f"\nreproduce: python tests/fuzz_exr.py --seed {SEED} --case N --save case.exr")


class _FakeWorker:
    """Stands in for the worker process: answers "hang" for the first `hangs` runs (over all instances, as a
    starved or a truly stuck worker would), then reads every case."""
    runs = 0
    hangs = 0

    def __init__(self, *args):
        pass

    def run(self, path, oiio, timeout):
        type(self).runs += 1
        if type(self).runs <= type(self).hangs:
            return "hang", None
        return "ok", [{"target": "info", "status": "ok", "detail": None, "cpu": 0.0, "peak": 0}]

    def close(self):
        pass


def test_a_timeout_counts_as_a_hang_only_when_it_repeats(monkeypatch):
    monkeypatch.setattr(fuzz_exr, "Worker", _FakeWorker)
    _FakeWorker.runs, _FakeWorker.hangs = 0, 1           # starved once: retried, then read
    summary = fuzz_exr.campaign(3, 1, oiio_every=0)
    assert summary["hang"] == 0 and summary["hang_retried"] == 1 and summary["read"] == 3
    _FakeWorker.runs, _FakeWorker.hangs = 0, 2           # stuck in the retry too: a hang
    summary = fuzz_exr.campaign(3, 1, oiio_every=0)
    assert summary["hang"] == 1 and summary["hang_retried"] == 0 and summary["read"] == 2
    assert summary["failures"][0]["case"] == 0 and summary["failures"][0]["status"] == "hang"
