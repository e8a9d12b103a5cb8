"""Paper §4.1, Figs. 2-3: the spinning rigid box with DS and CS (and DSn, MJ for error against time).

    python experiments/paper/paper_box.py [--out experiments/out/paper_box]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from _paper import finish, output_dir, run_study  # noqa: E402

from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax._studies import slopes  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

HS = [1e-4, 3e-4, 1e-3, 3e-3, 1e-2]


def main() -> None:
    out = output_dir(__doc__, "paper_box")
    rows, reference, elapsed = run_study("rigid_box", ["ds", "cs", "dsn", "mj"], HS, 1e-5, "cs", {}, out,
                                         max_iter_cs=200)
    by = {(r.scheme, r.h): r for r in rows}
    ok = [h for h in HS if not by[("ds", h)].failed_steps and not by[("cs", h)].failed_steps]
    ratio = [by[("ds", h)].errors["gap_5"] / by[("cs", h)].errors["gap_5"] for h in ok]

    def solves(scheme, h, stat):
        return by[(scheme, h)].iterations["linear_solves"][stat]

    fewer_mean = all(solves("ds", h, "mean") < solves("cs", h, "mean") for h in HS)
    fewer_max = all(solves("ds", h, "max") <= solves("cs", h, "max") for h in HS)
    order = slopes(rows)
    o_ds, o_cs = order.get(("ds", "gap_5"), float("nan")), order.get(("cs", "gap_5"), float("nan"))
    claims = [
        ("DS and CS converge at the same rate",
         f"order of gap_5: DS {o_ds:.2f}, CS {o_cs:.2f}", abs(o_ds - o_cs) < 0.3),
        ("DS and CS reach the same error",
         "error ratio DS/CS of gap_5: " + ", ".join(f"{h:g}: {r:.2f}" for h, r in zip(ok, ratio)),
         all(0.5 < r < 2.0 for r in ratio)),
        ("DS needs fewer iterations (average)", "mean solves/step DS vs CS: " + ", ".join(
            f"{h:g}: {solves('ds', h, 'mean'):.1f} vs {solves('cs', h, 'mean'):.1f}" for h in HS), fewer_mean),
        ("DS needs fewer iterations (maximum)", "max solves/step DS vs CS: " + ", ".join(
            f"{h:g}: {solves('ds', h, 'max')} vs {solves('cs', h, 'max')}" for h in HS), fewer_max),
    ]
    finish("rigid_box", rows, reference, elapsed, claims, out, "python experiments/paper/paper_box.py")


if __name__ == "__main__":
    main()
