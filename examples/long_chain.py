"""The critical moment of longer chains: M_c and phi_0 at the fold against N (the paper's Section 3 regime).

python examples/long_chain.py            # N = 3 ... 300
python examples/long_chain.py --quick    # N = 3, 10
"""

import argparse

from cosserat_chain import ChainParams, critical_point

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--quick", action="store_true", help="short chains only")
args = parser.parse_args()

lengths = (3, 10) if args.quick else (3, 10, 30, 100, 300)
print(f"{'N':>5} {'model':>10} {'M_c':>12} {'N M_c':>10} {'phi0 at fold':>13} {'folds':>6}")
for n in lengths:
    for model in ("sine", "nonlinear"):
        result = critical_point(ChainParams(N=n), model)
        print(
            f"{n:>5} {model:>10} {result.critical_moment:>12.6g} {n * result.critical_moment:>10.4g} {result.phi0_at_fold:>13.4g} {len(result.branch.folds):>6}"
        )
