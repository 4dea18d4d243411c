"""``ccjax calibrate``: fit camera sensors and linearisation to calibration data (Barnard 1999 ch. 3)."""

from __future__ import annotations

import sys
import time

from ccjax._numbers import decimal, whole
from ccjax.cli.common import check_outputs as check_files
from ccjax.cli.common import (
    check_plot,
    data_output_argument,
    int_list,
    overwrite_argument,
    seed,
    table_stream,
    write,
    write_plot,
)
from ccjax.cli.option_checks import data_folder


def add_calibrate(sub) -> None:
    p = sub.add_parser(
        "calibrate",
        help="fit camera sensors and linearisation to calibration data (thesis ch. 3)",
        description="Fit sensor curves and the linearisation F(x) = x - a0 - a1 exp(-C (x - b)) (thesis ch. 3) by "
        "every method of "
        "Table 3.1 and print the table. DATA is a CSV with one measurement per line: the spectrum at 380,384,...,780 "
        "nm "
        "(101 values) then the raw R,G,B (an optional header 380,...,780,R,G,B and '#' comment lines are allowed). "
        "--synthetic runs the thesis' experiment with a known camera (24 ColorChecker patches under 26 lights, noise, "
        "clipping, a known F) and checks the fits against the truth.",
    )
    p.add_argument("file", nargs="?", metavar="DATA", help="calibration CSV (see above)")
    p.add_argument(
        "--synthetic",
        action="store_true",
        help="run the thesis' synthetic experiment instead of reading DATA",
    )
    p.add_argument(
        "--camera",
        default=None,
        help="true camera for --synthetic (default: 'Sony DXC-930' when the external data is present, else 'Canon EOS "
        "5D Mark II')",
    )
    p.add_argument(
        "--data-dir",
        type=data_folder,
        default=None,
        help="external data directory (else $CCJAX_DATA, else ../shared/data)",
    )
    p.add_argument(
        "--seed",
        type=seed,
        default=0,
        help="seed of the synthetic data, the held-out split and the subsets",
    )
    p.add_argument(
        "--smoothness",
        type=decimal,
        default=None,
        help="lambda of the smoothness term (default: the library default, or --cv)",
    )
    p.add_argument(
        "--cv",
        action="store_true",
        help="choose the smoothness by 5-fold cross-validation of the joint fit",
    )
    p.add_argument(
        "--black",
        type=decimal,
        default=None,
        help="camera black b of F, raw units (default: 0 for DATA; the true 10 for --synthetic)",
    )
    p.add_argument(
        "--exp-rate",
        type=decimal,
        default=None,
        help="C of F (default: searched per channel)",
    )
    data_output_argument(p, "--json", "the RMS relative error of each method as a fraction")
    p.add_argument(
        "--plot",
        default=None,
        help="write a PNG of the fitted (and, with --synthetic, true) sensor curves",
    )
    p.add_argument("--save", default=None, help="write the proposed method's curves (and F) as CSV")
    p.add_argument(
        "--robustness",
        default=None,
        metavar="PNG",
        help="also run the robustness experiment (Fig. 3.6) and write its log-log plot",
    )
    p.add_argument(
        "--subsets",
        type=whole,
        default=100,
        help="random subsets per size for --robustness (default: %(default)s)",
    )
    p.add_argument(
        "--sizes",
        type=int_list,
        default=[400, 200, 100, 50, 25, 15],
        help="subset sizes for --robustness (default: 400,200,100,50,25,15)",
    )
    overwrite_argument(p, "--json, --plot, --save and --robustness files")
    p.set_defaults(func=run_calibrate)


def joint_exp_rate(table):
    """The per-channel C of F fitted by the joint (proposed) method of Table 3.1."""
    from ccjax.calibration.table import JOINT

    linearisation = table.row(JOINT).fit.linearisation
    if linearisation is None:  # the joint method always fits F; a table without it is a bug
        raise ValueError("calibration: the joint fit has no linearisation")
    return linearisation.exp_rate


def robustness_numbers(path: str) -> str:
    """The JSON written beside the ``--robustness`` plot: its name with ``.json``."""
    import os

    return os.path.splitext(path)[0] + ".json"


def check_outputs(args) -> None:
    """Refuse unwritable or clashing output files before any work (a bad path found after minutes of
    fitting would lose the run)."""
    outputs = [("--json", args.json), ("--plot", args.plot), ("--save", args.save), ("--robustness", args.robustness)]
    if args.robustness:
        outputs.append(("--robustness", robustness_numbers(args.robustness)))
    check_files([args.file] if args.file else [], outputs, overwrite=args.overwrite)
    check_plot(args.plot)
    check_plot(args.robustness, "--robustness")


def run_calibrate(args) -> int:
    import numpy as np

    from ccjax.calibration import (
        DEFAULT_SMOOTHNESS,
        experiment,
        has_external_lights,
        plots,
        read_calibration_csv,
        robustness,
        write_sensors_csv,
    )
    from ccjax.calibration import table as table_3_1

    start = time.perf_counter()
    if args.synthetic == (args.file is not None):
        raise ValueError("give either a calibration file DATA or --synthetic (not both)")
    if args.subsets < 1:
        raise ValueError(f"--subsets: expected a positive number, got {args.subsets}")
    if args.camera and not args.synthetic:
        raise ValueError("--camera applies to --synthetic only")
    check_outputs(args)
    out = table_stream(args)  # standard error when --json puts the data on standard output
    if args.synthetic:
        camera = args.camera
        if camera is None:  # say which camera was chosen and why, never switch silently
            if has_external_lights(args.data_dir):
                camera = "Sony DXC-930"
                print("camera: Sony DXC-930 (the thesis camera; --camera chooses another)", file=out)
            else:
                camera = "Canon EOS 5D Mark II"
                print(
                    "camera: Canon EOS 5D Mark II (the thesis' Sony DXC-930 curves are external data and were "
                    "not found: --data-dir or $CCJAX_DATA; --camera chooses another)",
                    file=out,
                )
        report = experiment.synthetic_experiment(
            camera,
            seed=args.seed,
            smoothness=args.smoothness,
            cv=args.cv,
            exp_rate=args.exp_rate,
            data_dir=args.data_dir,
        )
        table, truth = report.table, report.data.sensors
        spectra, raw = report.data.usable_data()
        black = report.data.linearisation.black[0]
        print(report.text(), file=out, flush=True)
        title = f"{camera}: fitted (solid) vs true (dashed) sensors"
    else:
        data = read_calibration_csv(args.file)
        spectra, raw = data.spectra, data.responses
        black = 0.0 if args.black is None else args.black
        smoothness = args.smoothness
        if args.cv:
            from ccjax.calibration import fit_sensors_cv

            _, cross_validation = fit_sensors_cv(
                spectra,
                raw,
                linearisation="exp",
                black=black,
                exp_rate=args.exp_rate,
                seed=args.seed,
            )
            smoothness = cross_validation.best
            print(cross_validation.table(), file=out)
        table = table_3_1.calibration_table(
            spectra,
            raw,
            black=black,
            exp_rate=args.exp_rate,
            smoothness=DEFAULT_SMOOTHNESS if smoothness is None else smoothness,
        )
        truth = None
        print(f"{args.file}: {len(spectra)} measurements", file=out)
        print(table.text(), file=out)
        rates = joint_exp_rate(table)
        print(file=out)
        print(
            table_3_1.held_out(
                spectra,
                raw,
                black=black,
                exp_rate=rates,
                smoothness=table.smoothness,
                seed=args.seed,
            ).text(),
            file=out,
            flush=True,
        )
        title = f"{args.file}: fitted sensors"
    if args.json:
        write(args.json, table.to_json(), overwrite=args.overwrite)
    if args.plot:
        write_plot(
            args.plot,
            lambda file: plots.plot_sensors(table, file, truth=truth, title=title),
            overwrite=args.overwrite,
        )
    if args.save:
        fit = table.row(table_3_1.JOINT).fit
        write_sensors_csv(args.save, np.asarray(fit.sensors), fit.linearisation, overwrite=args.overwrite)
        print(f"wrote {args.save}", file=sys.stderr)
    if args.robustness:
        sizes = [n for n in args.sizes if n < len(spectra)]
        if not sizes:
            raise ValueError(f"--sizes: every size is >= the {len(spectra)} measurements")
        rates = joint_exp_rate(table)
        result = robustness.robustness(
            spectra,
            raw,
            black=black,
            exp_rate=rates,
            smoothness=table.smoothness,
            sizes=sizes,
            n_subsets=args.subsets,
            seed=args.seed,
            progress=lambda size, label: print(
                f"  robustness: {size} measurements, {label} done ({time.perf_counter() - start:.0f} s)",
                file=sys.stderr,
                flush=True,
            ),
        )
        print("\n" + result.text(), file=out)
        title = f"robustness: {args.subsets} random subsets per size"
        write_plot(
            args.robustness,
            lambda file: plots.plot_robustness(result, file, title=title),
            overwrite=args.overwrite,
        )
        write(robustness_numbers(args.robustness), result.to_json(), overwrite=args.overwrite)
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


COMMANDS = [add_calibrate]
