"""Every benchmark and script answers `--help`, and takes the commands its module docstring documents: each
documented argument list is parsed by the script's own parser (not run: benchmarks take minutes to hours).
benchmarks/rl.py's sizes are checked for its GPU command and its CPU path is run at a tiny size."""

import ast
import importlib.util
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
# the scripts, not the modules they import (benchmarks/results_sections.py): what `python <file>` runs
SCRIPTS = sorted(p for p in [*(REPO / "benchmarks").glob("*.py"), *(REPO / "scripts").glob("*.py")]
                 if 'if __name__ == "__main__":' in p.read_text())
ENV = {**os.environ, "OMP_NUM_THREADS": "1"}

# In one subprocess for every script (a fresh interpreter per script cost 3-4 s of imports each), each script run
# as `python <script>` runs it: `--help` must exit 0; then main() runs once per documented argument list with
# ArgumentParser.parse_args stopping it right after a successful parse. Prints {script: [usage printed, error]}.
DRIVER = r"""
import argparse, contextlib, io, json, runpy, sys
from pathlib import Path


class Parsed(Exception):
    pass


parse = argparse.ArgumentParser.parse_args


def parse_only(self, args=None, namespace=None):
    parse(self, args, namespace)  # argparse exits 2, naming the argument, on one it does not take
    raise Parsed


def check(script, commands):
    sys.argv = [script, "--help"]
    argparse.ArgumentParser.parse_args = parse
    try:
        runpy.run_path(script, run_name="__main__")
    except SystemExit as exc:
        if exc.code not in (0, None):
            return f"--help exited {exc.code}"
    else:
        return "--help did not exit: the script has no argparse --help"
    argparse.ArgumentParser.parse_args = parse_only
    for args in commands:
        sys.argv = [script, *args]
        try:
            runpy.run_path(script, run_name="__main__")
        except Parsed:
            continue
        except SystemExit as exc:
            return f"{' '.join(args)}: exited {exc.code}"
        return f"{' '.join(args)}: main() ended without parsing its arguments"
    return None


results, path = {}, list(sys.path)
for script, commands in json.loads(sys.stdin.read()).items():
    sys.path[:] = [str(Path(script).parent), *path]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        error = check(script, commands)
    results[script] = [out.getvalue(), error and error + "\n" + err.getvalue()[-3000:]]
print(json.dumps(results))
"""


def documented_commands(path: Path) -> list[list[str]]:
    """The argument lists of the docstring's commands that run `path`: a line naming it, continued by a trailing
    backslash or by more deeply indented lines; a synopsis's [optional] brackets are dropped and the first of
    `a|b` alternatives taken."""
    lines = ast.get_docstring(ast.parse(path.read_text())).splitlines()
    name = f"{path.parent.name}/{path.name}"
    commands = []
    for i, line in enumerate(lines):
        if not re.search(rf"\bpython3? {re.escape(name)}(\s|$)", line):
            continue
        indent, text = len(line) - len(line.lstrip()), line
        for more in lines[i + 1:]:
            if not (text.endswith("\\") or (more.strip() and len(more) - len(more.lstrip()) > indent)):
                break
            text = text.removesuffix("\\") + " " + more.strip()
        tokens = shlex.split(text, comments=True)
        args = tokens[next(k for k, t in enumerate(tokens) if t.endswith(name)) + 1:]
        commands.append([_synopsis_token(t) for t in args if _synopsis_token(t)])
    return commands


def _synopsis_token(token: str) -> str:
    if token.startswith("[-"):  # an optional flag: [--reps 3], [--compile-only], [-- OVERRIDES]
        token = token[1:]
    while token.endswith("]") and token.count("]") > token.count("["):
        token = token[:-1]
    return token.split("|")[0]


def test_a_synopsis_is_read_as_its_arguments():
    path = REPO / "benchmarks" / "sim_throughput.py"
    assert documented_commands(path)[0][:4] == ["--tasks", "Pendulum,Humanoid", "--envs", "8192,32768"]
    assert "--impl" in documented_commands(path)[0] and documented_commands(path)[0][-1] == "auto"
    rl = documented_commands(REPO / "benchmarks" / "rl.py")
    assert rl[0] == [] and rl[1][:3] == ["--tasks", "Cartpole", "Ant"] and rl[1][-1] == "rl.train.epochs=5"


@pytest.fixture(scope="module")
def parsed() -> dict[str, list]:
    """Every script's [what it printed, its error or None], from one driver process."""
    commands = {str(path): documented_commands(path) for path in SCRIPTS}
    proc = subprocess.run([sys.executable, "-c", DRIVER], input=json.dumps(commands), cwd=REPO, env=ENV,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.splitlines()[-1])


@pytest.mark.xdist_group("documented_commands")
@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_help_and_the_documented_commands_parse(path, parsed):
    assert documented_commands(path), f"{path.name}'s docstring documents no `python {path.parent.name}/{path.name} ...` command"
    printed, error = parsed[str(path)]
    assert error is None, error
    assert re.search(r"^usage: ", printed, re.M), printed[:500]


def rl_benchmark():
    spec = importlib.util.spec_from_file_location("rl_benchmark", REPO / "benchmarks" / "rl.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_rl_benchmark_gpu_command_sizes_are_whole_batches():
    """The docstring's GPU command, built here on the CPU (nothing simulated; batch sizes do not depend on the
    device): 8,192 environments x 16 steps a batch."""
    args = documented_commands(REPO / "benchmarks" / "rl.py")[1]
    overrides = [*args[args.index("--overrides") + 1:], "device=cpu"]
    rl = rl_benchmark()
    assert rl.components("Cartpole", overrides, 262144)[1].train_cfg.total_steps == 262144  # 2 batches
    assert rl.components("Cartpole", overrides, 3_000_000)[1].train_cfg.total_steps == 23 * 8192 * 16  # rounded up


def test_rl_benchmark_runs_on_cpu_at_a_tiny_size():
    proc = subprocess.run([sys.executable, "benchmarks/rl.py", "--tasks", "Cartpole", "--steps", "100", "--solve-steps",
                           "40", "--overrides", "rl.train.num_envs=4", "rl.train.rollout_steps=8",
                           "rl.train.minibatch_size=16", "rl.train.epochs=1"], cwd=REPO, env=ENV, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    # native MuJoCo: no compiled row; the stepwise one over 100 steps rounded up to 4 batches of 32
    assert re.search(r"^\| Cartpole \| 4 x 8, 1 x 16 \| [\d,]+ \| - \| [\d,]+ \(", proc.stdout, re.M), proc.stdout
    assert re.search(r"^Cartpole \(stepwise.* 64 steps", proc.stdout, re.M), proc.stdout  # a budget of 40: 2 batches
