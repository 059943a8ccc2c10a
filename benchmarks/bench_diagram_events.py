"""CPU of one state-diagram row per kind of located end, and the located value: period doublings and tori taken from
the one mechanism (``cycle_curve.locate_circle_event``) against the augmented Newton (``locate_cycle_end``).

Run from the repository root, the new tree and an old one interleaved (one BLAS thread, CPU time)::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_diagram_events.py --label new
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=OLD/src python benchmarks/bench_diagram_events.py --label old

Each run appends one record (label, load average before and after, each row's end, rotation_stops, method and CPU
seconds) to ``benchmarks/results/diagram_events.json``. Rows: the paper's sine chain at gamma_phi = 0.15 (a period
doubling) and 0.1 (a torus), the nonlinear chain at gamma_phi = 0.2 (a period doubling).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import cosserat_chain
from cosserat_chain import ChainParams
from cosserat_chain.experiments import diagram

RESULTS = Path(__file__).parent / "results" / "diagram_events.json"
ROWS = (("sine", 0.15), ("sine", 0.1), ("nonlinear", 0.2))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--label", required=True, help="Names the tree measured (new, old, ...).")
    args = parser.parse_args()
    record = {"label": args.label, "package": cosserat_chain.__file__, "load_before": os.getloadavg(), "rows": []}
    for model, value in ROWS:
        start = time.process_time()
        row = diagram.state_diagram(ChainParams(), model, "gamma_phi", [value]).rows[0]
        cpu = time.process_time() - start
        record["rows"].append(
            {"model": model, "gamma_phi": value, "end": row.end, "rotation_stops": row.rotation_stops, "method": row.method, "cpu": cpu}
        )
    record["load_after"] = os.getloadavg()
    runs = json.loads(RESULTS.read_text()) if RESULTS.exists() else []
    RESULTS.write_text(json.dumps([*runs, record], indent=1) + "\n")
    print(json.dumps(record))


if __name__ == "__main__":
    main()
