"""The report of benches/peers/mbpo_pair.sh (standard library only).

  mbpo_pair_report.py run tandem DIR   one tandem run: DIR is its study directory
  mbpo_pair_report.py run mbrl DIR     one mbrl-lib run: DIR holds mbpo_mbrl.py's timing.json
  mbpo_pair_report.py pairs OUT        every run under OUT (tandem_<i>, mbrl_<i>) and the ratios
                                       tandem/mbrl-lib, the median over the pairs with both sides

Each run's wall time is the library's own measure of the run (tandem's record.json
`wall_seconds`: MBPO's run; mbrl-lib's: `mbpo.train`), and its split: SAC updates, model training,
model rollouts, and the rest (real steps, acting, evaluation, saving). The returns are the
evaluations' (one episode each), a check that both sides learned alike, not a result.
"""
import glob
import json
import os
import re
import statistics
import sys

PARTS = ["wall", "sac", "fit", "rollouts", "rest"]
HEADER = (f"{'run':<13}{'wall s':>9}{'SAC upd s':>11}{'model fit s':>13}{'rollouts s':>12}"
          f"{'rest s':>9}{'updates':>9}{'refits':>8}  returns (real step: return)")


def tandem_run(study):
    """The MBPO record of a `tandem reproduce p3-mujoco --methods mbpo` study directory."""
    paths = glob.glob(os.path.join(study, "runs", "mbpo__seed*", "record.json"))
    if len(paths) != 1:
        raise SystemExit(f"mbpo_pair_report.py: expected one MBPO record.json under {study}/runs, "
                         f"found {len(paths)}")
    with open(paths[0]) as f:
        r = json.load(f)
    parts = r["update_seconds"] + r["fit_seconds"] + r["imagine_seconds"]
    return {
        "wall": r["wall_seconds"], "sac": r["update_seconds"], "fit": r["fit_seconds"],
        "rollouts": r["imagine_seconds"], "rest": r["wall_seconds"] - parts,
        "updates": r["updates"], "refits": len(r["fit_holdout_loss"]),
        "returns": [(p["true_samples"], p["eval_return"]) for p in r["curve"]],
    }


def mbrl_run(d):
    with open(os.path.join(d, "timing.json")) as f:
        r = json.load(f)
    return {
        "wall": r["wall_seconds"], "sac": r["sac_update_seconds"], "fit": r["fit_seconds"],
        "rollouts": r["rollout_seconds"], "rest": r["rest_seconds"],
        "updates": r["sac_updates"], "refits": r["model_fits"],
        "returns": list(zip(r["eval_steps"], r["eval_returns"])),
    }


def line(name, r):
    returns = "  ".join(f"{s}: {v:.0f}" for s, v in r["returns"])
    return (f"{name:<13}{r['wall']:>9.1f}{r['sac']:>11.1f}{r['fit']:>13.1f}{r['rollouts']:>12.1f}"
            f"{r['rest']:>9.1f}{r['updates']:>9}{r['refits']:>8}  {returns}")


def pairs(out):
    def runs(side, read):
        found = {}
        for d in glob.glob(os.path.join(out, f"{side}_*")):
            m = re.fullmatch(rf"{side}_(\d+)", os.path.basename(d))
            if m and os.path.isdir(d):
                try:
                    found[int(m.group(1))] = read(d)
                except (OSError, KeyError, SystemExit) as e:
                    print(f"({side} {m.group(1)}: no finished run: {e})")
        return found

    tandem, mbrl = runs("tandem", tandem_run), runs("mbrl", mbrl_run)
    print(HEADER)
    for i in sorted(set(tandem) | set(mbrl)):
        if i in tandem:
            print(line(f"tandem {i}", tandem[i]))
        if i in mbrl:
            print(line(f"mbrl-lib {i}", mbrl[i]))
    both = sorted(set(tandem) & set(mbrl))
    if not both:
        print("no pair with both sides: no ratio")
        return
    print(f"ratio tandem / mbrl-lib, median over {len(both)} pair(s) (each pair's in brackets):")
    for part, label in zip(PARTS, ["wall", "SAC updates", "model training", "model rollouts",
                                   "rest"]):
        ratios = [tandem[i][part] / mbrl[i][part] if mbrl[i][part] > 0 else float("nan")
                  for i in both]
        each = " ".join(f"{x:.2f}" for x in ratios)
        print(f"  {label:<15} {statistics.median(ratios):.2f}  [{each}]")
    for i in both:
        if tandem[i]["updates"] != mbrl[i]["updates"] or tandem[i]["refits"] != mbrl[i]["refits"]:
            print(f"  pair {i}: the sides did different work (updates {tandem[i]['updates']} "
                  f"against {mbrl[i]['updates']}, refits {tandem[i]['refits']} against "
                  f"{mbrl[i]['refits']}): the ratios compare unlike runs")


def main(argv):
    if len(argv) == 4 and argv[1] == "run" and argv[2] in ("tandem", "mbrl"):
        r = tandem_run(argv[3]) if argv[2] == "tandem" else mbrl_run(argv[3])
        print(HEADER)
        print(line("tandem" if argv[2] == "tandem" else "mbrl-lib", r))
    elif len(argv) == 3 and argv[1] == "pairs":
        pairs(argv[2])
    else:
        raise SystemExit(__doc__)


if __name__ == "__main__":
    main(sys.argv)
