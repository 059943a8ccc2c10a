"""A parameter study on Dask: M_c and the compliance over the particles' half-width a and the diagonal stiffness E2.

    python examples/parameter_study.py            # 6 x 5 cells, two models
    python examples/parameter_study.py --quick    # 2 x 2 cells

To use an existing cluster, pass its address: --scheduler tcp://HOST:8786.
"""

import argparse

from cosserat_chain import run_study, spec_from_mapping

if __name__ == "__main__":  # Dask's worker processes import this file again
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a small grid")
    parser.add_argument("--scheduler", default=None)
    parser.add_argument("--out", default="study.nc")
    args = parser.parse_args()
    size = 2 if args.quick else 6
    spec = spec_from_mapping(
        {
            "models": ["nonlinear", "sine"],
            "quantities": ["M_c", "compliance"],
            "parameters": {
                "a": {"start": 0.1, "stop": 0.3, "num": size},
                "E2": {"start": 0.25, "stop": 4.0, "num": max(2, size - 1), "scale": "log"},
            },
        }
    )
    run = run_study(spec, out=args.out, scheduler=args.scheduler, workers=None if args.scheduler else 2)
    print(f"{run.computed} cells computed, {run.skipped} read back, {run.failed} failed; wrote {args.out}")
    print(run.dataset.M_c.sel(model="nonlinear").to_pandas())
