"""Replicate study of ``millflow diagnose`` (docs/model-error.md, "Does diagnose choose the
truth?"): truths from each class (linear, slowing-down s = 1, cushioning s = 1,
aggregation beta0 = 0.01 1/s) on the batch design of the worked studies with 1 % noise;
how often diagnose chooses the truth's class, and how often the chosen model's 95 %
intervals hold the truth (:mod:`millflow.falsify.diagnose_study`).

    python examples/model_error/diagnose_study.py [--replicates R] [--workers W] [--out FILE]

Writes the summary (rates with 95 % Clopper-Pearson intervals, and every replicate's
choice, estimates and coverage) as JSON, by default diagnose_study_summary.json beside
this script; prints the table.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))

from millflow.falsify.diagnose_study import TRUTH_CLASSES, diagnose_study, format_summary, summarize  # noqa: E402,E501


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--replicates", type=int, default=50, help="replicates per truth (default 50)")
    ap.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--first", type=int, default=0, help="index of the first replicate (extend a run)")
    ap.add_argument("--merge", nargs="*", default=[], help="summaries of other replicates to add to this one")
    ap.add_argument("--strength", nargs=2, action="append", default=[], metavar=("TRUTH", "S"),
                    help="another strength for a truth class, e.g. --strength cushioning 1.5")
    ap.add_argument("--truths", nargs="*", default=list(TRUTH_CLASSES), choices=list(TRUTH_CLASSES))
    ap.add_argument("--out", default=str(HERE / "diagnose_study_summary.json"))
    a = ap.parse_args(argv)
    done = [0]

    def say(rec):
        done[0] += 1
        print(f"[{done[0]}] {rec['truth']} r{rec['replicate']}: {rec.get('best', 'failed')} "
              f"({rec['runtime_s']:.1f} s)", file=sys.stderr, flush=True)

    res = diagnose_study(a.replicates, truths=tuple(a.truths), seed=a.seed, workers=a.workers, first=a.first,
                         strengths={k: float(v) for k, v in a.strength}, progress=say)
    if a.merge:  # the same study over more replicates (same seed, other replicate indices)
        recs = res["replicates"] + [r for f in a.merge for r in json.loads(Path(f).read_text())["replicates"]]
        seen = {(r["truth"], r["replicate"]) for r in res["replicates"]}
        if len(seen) + sum(len(json.loads(Path(f).read_text())["replicates"]) for f in a.merge) != len(
                {(r["truth"], r["replicate"]) for r in recs}):
            raise SystemExit("--merge: the summaries share replicates")
        res.update(summarize(recs), replicates=recs, replicates_per_truth=len(recs) // len(res["truths"]))
    Path(a.out).write_text(json.dumps(res, indent=1, default=float) + "\n", encoding="utf-8")
    print(format_summary(res))
    print(f"{res['runtime_s']:.0f} s with {a.workers} workers; summary in {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
