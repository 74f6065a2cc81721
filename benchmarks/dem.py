"""DEM throughput: particle-steps per second of the default scene's flow, dpht's decks against
LIGGGHTS' plain settings, at 1 and 2 MPI ranks.

    python benchmarks/dem.py                   # 0.03 s of flow from the settled bed, 3 rounds
    python benchmarks/dem.py --flow-time 0.05 --rounds 5
    python benchmarks/dem.py --partial         # also a bed filling 14 of the tube's 50 mm
    python benchmarks/dem.py --tiny            # the test suite's run: the tiny scene, 1 round of 0.002 s

Set-up (once, kept in --workdir while the decks do not change): the gmsh geometry of
config/config.yaml (with ``--tiny``, of .test/config/config.yaml) and LIGGGHTS' fill and settle at 2
ranks; the zone STLs merged into the one wall mesh the decks read, as the DEM stage does. Then rounds of short flows from the
settled bed, each round running every setting once, alternating, so that the machine's drift hits
all alike; the table gives medians over the rounds, the ratios are medians of each round's ratio. A particle-step is one particle advanced one DEM
step; the speed is particles x steps / LIGGGHTS' own loop time (set-up and reading excluded).
"dpht" is the flow deck the workflow runs; "plain" the same deck without its ``processors``,
``neighbor`` and ``neigh_modify`` lines: the processor grid LIGGGHTS chooses from the box shape and
its default neighbour settings (skin 1 mm in SI units, rebuild checks from 10 steps on).
``--partial`` compares the processor grids on a partly filled tube (dpht's choice against LIGGGHTS').

The last line printed is ``dem speed-up over plain settings: VALUE`` (2 ranks). The load average is
printed too: at 2 ranks every step waits for both ranks, so other work on the cores shows directly.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from dpht import config  # noqa: E402
from dpht.dem.decks import SETTLED_RESTART, render_decks  # noqa: E402
from dpht.dem.liggghts import _stage_meshes as stage_meshes, run_liggghts  # noqa: E402
from dpht.dem.params import DemParams, read_geometry  # noqa: E402
from dpht.errors import ExternalToolError  # noqa: E402

LOOP = re.compile(r"Loop time of (\S+) on (\d+) procs for (\d+) steps with (\d+) atoms")
NLOCAL = re.compile(r"Nlocal:\s+(\S+) ave\s+(\S+) max")
NEIGHS = re.compile(r"Ave neighs/atom = (\S+)")
DANGEROUS = re.compile(r"Dangerous builds = (\d+)")
PLAIN_DROPS = ("processors", "neighbor", "neigh_modify")


DEFAULT, TINY = ROOT / "config" / "config.yaml", ROOT / ".test" / "config" / "config.yaml"


def prepare(workdir: Path, fill_height: float | None, flow_time: float, scene: Path = DEFAULT) -> tuple[DemParams, str]:
    """Geometry and settled bed of the ``scene`` config in ``workdir``; returns the params and flow deck."""
    from dpht.geometry import build

    cfg = config.variant(config.load(scene), "base")
    spec = config.dem_spec(cfg)
    spec["dem"]["flow_time"] = flow_time
    if fill_height is not None:
        spec["dem"]["fill_height"] = fill_height
    workdir.mkdir(parents=True, exist_ok=True)
    if not (workdir / "geometry" / "geometry.json").is_file():
        build(spec["geometry"], spec["particles"]["diameter"], workdir / "geometry")
    params = DemParams.from_spec(spec, read_geometry(workdir / "geometry"))
    stage_meshes(params.mesh_zones, workdir / "geometry", workdir)
    decks = render_decks(params)
    settle = workdir / "settle.in"
    if not (workdir / SETTLED_RESTART).is_file() or not settle.is_file() or settle.read_text() != decks["settle.in"]:
        settle.write_text(decks["settle.in"])
        (workdir / "settle").mkdir(exist_ok=True)
        print(f"settling {params.n_particles} particles in {workdir} (2 ranks) ...", flush=True)
        wall = run_liggghts("settle.in", workdir, workdir / "settle" / "screen.txt", ranks=2,
                            variables={"pz": str(params.z_slabs(2))})  # fmt: skip
        print(f"settled in {wall:.0f} s", flush=True)
    for sub in ("flow/restart", "flow/post"):
        (workdir / sub).mkdir(parents=True, exist_ok=True)
    return params, decks["flow.in"]


def plain(deck: str) -> str:
    return "\n".join(line for line in deck.splitlines() if line.split()[:1] not in [[w] for w in PLAIN_DROPS]) + "\n"


def flow(workdir: Path, name: str, deck: str, ranks: int, pz: str) -> dict:
    """One short flow from the settled bed; LIGGGHTS' own counts for it."""
    shutil.rmtree(workdir / "flow" / "post")
    (workdir / "flow" / "post").mkdir()
    (workdir / f"{name}.in").write_text(deck)
    screen = workdir / f"{name}.{ranks}.screen.txt"
    variables = {"restart_file": SETTLED_RESTART, "pz": pz}
    try:
        run_liggghts(f"{name}.in", workdir, screen, ranks=ranks, variables=variables)
    except ExternalToolError as err:  # on a shared machine a run can be killed from outside: once more
        if "killed by signal" not in str(err):
            raise
        print(f"  {name} at {ranks} ranks was killed from outside; running it again", flush=True)
        run_liggghts(f"{name}.in", workdir, screen, ranks=ranks, variables=variables)
    text = screen.read_text()
    loop, _, steps, atoms = LOOP.findall(text)[-1]
    ave, most = map(float, NLOCAL.findall(text)[-1])
    return {
        "speed": int(atoms) * int(steps) / float(loop),
        "imbalance": most / ave,
        "neighbours": float(NEIGHS.findall(text)[-1]),
        "dangerous": int(DANGEROUS.findall(text)[-1]),
        "grid": re.findall(r"(\d+ by \d+ by \d+) MPI processor grid", text)[-1],
        "particles": int(atoms),
        "steps": int(steps),
    }


def compare(workdir: Path, settings: dict[str, tuple[str, int, str]], rounds: int) -> dict[str, list[dict]]:
    runs = {name: [] for name in settings}
    for k in range(rounds):
        for name, (deck, ranks, pz) in settings.items():
            result = flow(workdir, re.sub(r"\W+", "_", name), deck, ranks, pz)
            runs[name].append(result)
            print(f"  round {k + 1}/{rounds}  {name:<22s} {result['speed']:.3g} particle-steps/s", flush=True)
    return runs


def median(runs: list[dict], key: str = "speed") -> float:
    return statistics.median(run[key] for run in runs)


def paired(a: list[dict], b: list[dict]) -> float:
    """Median over rounds of a's speed over b's in the same round (robust to the machine's drift)."""
    return statistics.median(x["speed"] / y["speed"] for x, y in zip(a, b))


def table(runs: dict[str, list[dict]]) -> None:
    print(f"{'setting':<22s} {'grid':>12s} {'particle-steps/s':>17s} {'range':>17s} {'max/mean':>9s} "
          f"{'neighbours':>10s} {'dangerous':>9s}")  # fmt: skip
    for name, rs in runs.items():
        speeds = [r["speed"] for r in rs]
        print(f"{name:<22s} {rs[0]['grid']:>12s} {median(rs):>17.3g} {min(speeds):>8.3g}-{max(speeds):<8.3g} "
              f"{median(rs, 'imbalance'):>9.3f} {median(rs, 'neighbours'):>10.2f} {max(r['dangerous'] for r in rs):>9d}")  # fmt: skip


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--flow-time", type=float, default=0.03, help="s of flow per run (default 0.03)")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds (default 3)")
    parser.add_argument("--partial", action="store_true", help="also the processor grids on a partly filled tube")
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/dpht-benchmark-dem"))
    parser.add_argument("--tiny", action="store_true", help="the tiny scene, one round of 0.002 s (seconds; the tests)")
    args = parser.parse_args(argv)
    if args.tiny:
        args.flow_time, args.rounds, args.partial = 0.002, 1, False
    print("load average (1, 5, 15 min) at the start: " + ", ".join(f"{x:.1f}" for x in os.getloadavg()))

    if args.partial:
        workdir = args.workdir / "partial"
        params, deck = prepare(workdir, 0.014, args.flow_time)
        print(f"partly filled tube: {params.n_particles} particles, bed of 14 mm in the 50 mm periodic tube")
        runs = compare(workdir, {"dpht grid @2": (deck, 2, str(params.z_slabs(2))), "LIGGGHTS grid @2": (deck, 2, "*")},
                       args.rounds)  # fmt: skip
        table(runs)
        print(f"partly filled tube: dpht's grid over LIGGGHTS' grid at 2 ranks: "
              f"{paired(runs['dpht grid @2'], runs['LIGGGHTS grid @2']):.2f}")  # fmt: skip

    workdir = args.workdir / ("tiny" if args.tiny else "default")
    params, deck = prepare(workdir, None, args.flow_time, TINY if args.tiny else DEFAULT)
    print(f"{'tiny' if args.tiny else 'default'} scene: {params.n_particles} particles, {args.flow_time} s of flow = "
          f"{round(args.flow_time / params.timestep)} steps per run")  # fmt: skip
    settings = {
        f"{name} @{ranks}": (text, ranks, str(params.z_slabs(ranks)))
        for ranks in (1, 2)
        for name, text in (("dpht", deck), ("plain", plain(deck)))
    }
    runs = compare(workdir, settings, args.rounds)
    table(runs)
    print("load average (1, 5, 15 min) at the end: " + ", ".join(f"{x:.1f}" for x in os.getloadavg()))
    for name in ("dpht", "plain"):
        scaling = paired(runs[f"{name} @2"], runs[f"{name} @1"])
        print(f"strong scaling 1 -> 2 ranks, {name}: {scaling:.2f} (parallel efficiency {scaling / 2:.0%})")
    print(f"dem speed-up over plain settings at 1 rank: {paired(runs['dpht @1'], runs['plain @1']):.2f}")
    print(f"dem speed-up over plain settings: {paired(runs['dpht @2'], runs['plain @2']):.2f}")


if __name__ == "__main__":
    main()
