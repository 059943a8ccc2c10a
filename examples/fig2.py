"""The paper's Fig. 2: phi_0 against M for the three models, exactly and by the relaxation protocol.

python examples/fig2.py            # the paper's load steps (dm = 0.01), about a minute
python examples/fig2.py --quick    # coarse steps, a few seconds
"""

import argparse

from cosserat_chain import ChainParams, critical_point, relaxation_sweep
from cosserat_chain.io import write_figure
from cosserat_chain.plots.statics import figure2

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--quick", action="store_true", help="coarse load steps")
parser.add_argument("--out", default="fig2.png")
args = parser.parse_args()

params = ChainParams()  # the paper's seven particles
exact = {model: critical_point(params, model) for model in ("nonlinear", "sine", "linear")}
dm = 0.05 if args.quick else 0.01
sweeps = {model: relaxation_sweep(params, model, m_max=0.3, dm=dm, down=True) for model in exact}
for model in exact:
    print(f"{model:10s} M_c = {exact[model].critical_moment}  onset (relaxation, dm = {dm}) = {sweeps[model].onset_load}")
write_figure(figure2(exact, sweeps), args.out, dpi=130)
print(f"wrote {args.out}")
