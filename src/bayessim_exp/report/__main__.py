"""`python -m bayessim_exp.report <sweep dir> [--out DIR] [--no-posteriors] [--pool]`: tables and plots of a sweep."""

import argparse
import sys

from .build import build_report
from .hparams import write_hparams


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bayessim_exp.report", description=__doc__)
    parser.add_argument("sweep_dir", help="a --multirun sweep dir (or one run dir)")
    parser.add_argument("--out", default=None, help="where to write the report (default: <sweep dir>/report)")
    parser.add_argument("--no-posteriors", action="store_true", help="skip the posterior pair plots")
    parser.add_argument("--pool", action="store_true",
                        help="one configuration for every job: a study run in parts whose overrides differ only in "
                             "where they ran (device=cuda on one machine, the CPU on another); link the parts' job "
                             "dirs into one folder")
    args = parser.parse_args(argv)
    try:
        report = build_report(args.sweep_dir, args.out, posteriors=not args.no_posteriors, pool=args.pool)
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{len(report.jobs)} jobs: {report.count('finished')} finished, {report.count('failed')} failed, "
          f"{report.count('unfinished')} unfinished")
    for job in report.jobs:
        if job.status != "finished":
            print(f"  {job.status}: {job.path}: {job.problem}")
    print(f"wrote {report.out_dir}/report.md, summary.csv, jobs.csv and {len(report.figures)} PNGs")
    try:
        written = write_hparams(args.sweep_dir)
    except Exception as exc:  # noqa: BLE001 - the report stands without TensorBoard's view
        print(f"TensorBoard hparams not written: {type(exc).__name__}: {exc}", file=sys.stderr)
    else:
        if written:
            print(f"wrote TensorBoard hparams of {len(written)} finished jobs: tensorboard --logdir {args.sweep_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
