"""The root README's table "The papers' claims, measured", generated from the experiments' stamped results files.

One row per claim of the papers tested here (:data:`CLAIMS`): where it was tested, the effect per seed (per run)
read from the results files, the claimed direction and the rule that decides it. One function decides every
verdict (:func:`verdict`, the rule of docs/design.md §11):

* **holds**: the registered rule passes. Where an experiment registered none, the t-based 95 % interval of the
  mean effect over seeds excludes zero on the claimed side (rule ``"t"``). Registered rules: ZeroEGGS's
  claims hold when their per-run rule holds in the stated count of runs (``"count"``: 4 of 5 seeds, zero-shot 2
  of 2; experiments/zeggs_claims/README.md); Bandai-Namco-2's relations when the mean over pairs is beyond 2
  standard errors over pairs with the claimed sign in each of the 3 seeds (``"pairs"``;
  experiments/tgst_bandai2/README.md).
* otherwise **same sign, not significant** when the mean effect has the claimed sign, else **does not hold**.

Beside each verdict the effect: its mean and interval (or range over runs, or SE over pairs) and, where a floor
(or reference) exists, the share of the gap it closes in the claimed direction.

    python -m experiments table claims     # rewrite the table in README.md
    python -m experiments table --check    # exit 1 when it (or an experiment table) differs from the results
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import math
import re
from typing import Callable

import numpy as np

from experiments.driver import REPO, ROOT, DriverError, load_config

#: two-sided 95 % quantiles of Student's t (0.975), by degrees of freedom (tests/unit/test_claims.py checks
#: them against scipy, a test dependency only)
T975 = {1: 12.7062, 2: 4.3027, 3: 3.1824, 4: 2.7764, 5: 2.5706, 6: 2.4469, 7: 2.3646, 8: 2.3060, 9: 2.2622,
        10: 2.2281, 11: 2.2010, 12: 2.1788, 13: 2.1604, 14: 2.1448, 15: 2.1314, 16: 2.1199, 17: 2.1098,
        18: 2.1009, 19: 2.0930, 20: 2.0860, 21: 2.0796, 22: 2.0739, 23: 2.0687, 24: 2.0639, 25: 2.0595,
        26: 2.0555, 27: 2.0518, 28: 2.0484, 29: 2.0452, 30: 2.0423}

HOLDS, SAME_SIGN, FAILS = "holds", "same sign, not significant", "does not hold"
README = REPO / "README.md"
START, END = "<!-- claims -->", "<!-- /claims -->"
BLOCK = re.compile(re.escape(START) + r"\n.*?" + re.escape(END), re.S)


@dataclasses.dataclass(frozen=True)
class Effect:
    """The effect of one claim in one condition, oriented as measured (``sign`` gives the claimed direction)."""

    values: tuple              # the effect per seed ("t", "pairs") or per run ("count")
    sign: int                  # the claimed direction of the effect: +1 or -1
    label: str = ""            # the condition ("intra", "other hand"), "" for a row with one
    rule: str = "t"            # "t", "count" or "pairs" (module docstring)
    passed: tuple = ()         # "count": whether each run passed its registered per-run rule
    need: int = 0              # "count": runs needed; "pairs": seeds needed
    pairs: tuple = ()          # "pairs": (mean, standard error, number) over pairs
    share: float | None = None  # the effect in the claimed direction over a gap (or a reference), a fraction
    of: str = "{p} % of the gap"  # how ``share`` is shown (``p``: the percentage)
    unit: str = ""
    digits: int = 3
    text: str = ""             # the number as shown, when not the generic mean and interval
    prefix: str = ""           # what the number is, when the claim does not say


def interval(values) -> tuple[float, float, float]:
    """Mean and t-based 95 % interval over ``values`` (unbounded for fewer than 2)."""
    from experiments.tables import _mean_se

    m, se = _mean_se(values)
    if len(values) < 2:
        return m, -math.inf, math.inf
    half = T975[min(len(values) - 1, 30)] * se
    return m, m - half, m + half


def verdict(e: Effect) -> str:
    """The verdict of one effect under its rule (module docstring; docs/design.md §11)."""
    if e.sign not in (1, -1):
        raise ValueError(f"sign must be +1 or -1, not {e.sign}")
    if e.rule == "t":
        m, lo, hi = interval(e.values)
        ok = lo > 0 if e.sign > 0 else hi < 0
    elif e.rule == "count":
        if len(e.passed) != len(e.values) or e.need < 1:
            raise ValueError("a count rule needs one passed flag per run and a count of runs")
        m, ok = float(np.mean(e.values)), sum(bool(p) for p in e.passed) >= e.need
    elif e.rule == "pairs":
        m, se, _ = e.pairs
        ok = (e.sign * m > 2 * se and len(e.values) >= e.need and all(e.sign * v > 0 for v in e.values))
    else:
        raise ValueError(f"unknown rule {e.rule!r}")
    if ok:
        return HOLDS
    return SAME_SIGN if e.sign * m > 0 else FAILS


def _num(x: float, digits: int, signed: bool = True) -> str:
    x = 0.0 if round(x, digits) == 0 else x  # no "-0.000"
    return (f"{x:+.{digits}f}" if signed else f"{x:.{digits}f}").replace("-", "−")


def effect_text(e: Effect) -> str:
    """The number beside a verdict: mean and interval (or the rule's own spread), then the share of the gap."""
    unit = f" {e.unit}" if e.unit else ""
    if e.text:
        out = e.text
    elif e.rule == "t":
        m, lo, hi = interval(e.values)
        out = (f"{_num(m, e.digits)} [{_num(lo, e.digits)}, {_num(hi, e.digits)}]{unit}" if len(e.values) > 1
               else f"{_num(m, e.digits)}{unit} (one measurement)")
    elif e.rule == "pairs":
        m, se, _ = e.pairs
        out = f"{_num(m, e.digits)} ± {_num(se, e.digits, False)}{unit}"
    else:
        out = f"{_num(min(e.values), e.digits)} to {_num(max(e.values), e.digits)}{unit}"
    if e.rule == "count":
        out += f", {sum(map(bool, e.passed))}/{len(e.passed)} pass"
    if e.share is not None:
        out += "; " + e.of.format(p=_num(100 * e.share, 0, signed=False))
    return f"{e.prefix} {out}" if e.prefix else out


def rule_text(e: Effect) -> str:
    """The rule in the table's words (legend under the table)."""
    if e.rule == "t":
        return f"{len(e.values)} seeds, t" if len(e.values) > 1 else "one measurement"
    if e.rule == "count":
        return f"reg. {e.need} of {len(e.values)} runs"
    return f"{len(e.values)} seeds, reg. 2 SE"


@dataclasses.dataclass(frozen=True)
class Claim:
    paper: str
    claim: str
    data: str                 # the data set, linked to the experiment's README (then ``where``, each effect's label)
    experiment: str           # the experiment folder
    effects: Callable         # () -> list of Effect (one per condition: one row each)
    where: str = ""


def rows(c: Claim) -> list[str]:
    """One table row per condition of the claim: verdict, effect, data and rule, the experiment."""
    data = f"[{c.data}][{c.experiment}]" + (f"{c.where}" if c.where else "")
    return [f"| {c.paper} | {c.claim} | **{verdict(e)}** | {effect_text(e)} | "
            f"{data}{' ' + e.label if e.label else ''}, {rule_text(e)} |" for e in c.effects()]


# --- reading the results files ---------------------------------------------------------------------------------

def _module(path: str, name: str):
    """An experiment's own table module (its functions read its results files)."""
    spec = importlib.util.spec_from_file_location(name, ROOT / path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@functools.lru_cache(maxsize=None)
def _driver_results(config: str) -> dict:
    from experiments.tables import load_config_results

    res = load_config_results(load_config(ROOT / config))
    if res is None or res["_missing"]:
        raise FileNotFoundError(f"{config}: results missing")
    return res


def _bn1(name: str) -> dict:
    return _driver_results(f"tgst_bandai/configs/{name}.toml")


def _err(pair: dict, name: str, group: str):
    e = (pair["controls"] if name.endswith("_as_is") else pair["errors"]).get(name)
    return None if not e else e.get(group)


def _per_seed(res: dict, cond: str, terms: Callable, group: str, names: tuple) -> list:
    """Per seed: ``terms(*errors)`` averaged over the pairs where every named method or control has ``group``."""
    out = []
    for per in res["seeds"].values():
        v = [[_err(p, n, group) for n in names] for p in per["eval"][cond]["per_pair"]]
        out.append(float(np.mean([terms(*x) for x in v if None not in x])))
    return out


def _bn1_gap(cond: str, method: str, control: str, floor: str, group: str, sign: int, label: str) -> Effect:
    """``method - control`` per seed; share: (control - method) / (control - floor) on the same pairs."""
    res = _bn1("fit_motion")
    d = _per_seed(res, cond, lambda m, c: m - c, group, (method, control))
    num = _per_seed(res, cond, lambda m, c, f: c - m, group, (method, control, floor))
    den = _per_seed(res, cond, lambda m, c, f: c - f, group, (method, control, floor))
    unit = "m/s" if group == "style" else "m"
    return Effect(tuple(d), sign, label, share=float(np.mean(num) / np.mean(den)), unit=unit)


def _bn1_soft_vs_hard(cond: str) -> Effect:
    res = _bn1("fit_motion")
    d = _per_seed(res, cond, lambda s, h: s - h, "style", ("soft", "hard"))
    gap = _per_seed(res, cond, lambda s, h, f: h - f, "style", ("soft", "hard", "style_as_is"))
    return Effect(tuple(d), -1, cond, share=float(-np.mean(d) / np.mean(gap)), of="{p} % of hard's gap to the floor",
                  unit="m/s")


def _bn1_table1() -> list:
    rows = _bn1("fit_motion")["metric_validity"]["rows"]
    content, style = rows["content"]["style"]["mean"], rows["style"]["style"]["mean"]
    return [Effect((style - content,), -1, text=f"style sample {style:.2f} vs content sample {content:.2f} m/s "
                   "(should be lower)")]


def _ablation(term: str, group: str) -> list:
    full, abl = _bn1("fit_motion"), _bn1(f"ablate_{term}")
    out = []
    for cond in ("intra", "inter"):
        seeds = [s for s in abl["seeds"] if s in full["seeds"]]
        get = lambda res, s: res["seeds"][s]["eval"][cond]["methods"]["soft"][group]["mean"]
        d = [get(abl, s) - get(full, s) for s in seeds]
        ref = float(np.mean([get(full, s) for s in seeds]))
        out.append(Effect(tuple(d), +1, cond, share=float(np.mean(d)) / ref, of=f"{{p}} % of the {group} error",
                          unit="m/s" if group == "style" else "m"))
    return out


def _bn2():
    return _module("tgst_bandai2/tables.py", "_claims_tgst_bandai2")


@functools.lru_cache(maxsize=None)
def _bn2_runs():
    t = _bn2()
    runs = [(f"full_s{s}", r) for s, r in t.seeds_of("full")]
    if len(runs) != 3:
        raise FileNotFoundError("tgst_bandai2: results of the 3 full runs missing")
    return runs[0][1], runs


BN2_LABELS = {"inter-mirror": "other hand", "inter-other": "other gesture"}  # the exemplar's


def _bn2_relation(method: str, a: str, err: str, control: str, cond: str) -> Effect:
    """``method - a`` on ``err`` over pairs (Bandai-Namco-2's registered rule); share: of ``control``'s gap to a
    ground-truth take (the experiment's jackknife share)."""
    t = _bn2()
    controls, runs = _bn2_runs()
    m, se, n, per, _ = t.paired(controls, runs, cond, a, method, err)
    s = t.share(controls, runs, cond, control, err, method=method)
    return Effect(tuple(per), -1, BN2_LABELS[cond], rule="pairs", need=3, pairs=(m, se, n), share=s[0],
                  unit="m" if err == "gt_content" else "m/s")


def _bn2_soft_vs_next(cond: str) -> Effect:
    t = _bn2()
    controls, runs = _bn2_runs()
    g = {m: t.mean_row(controls, runs, cond, f"{m}|mirror", "gt_style")[0] for m in t.METHODS}
    best = min((m for m in g if m != "soft"), key=g.get)
    m, se, n, per, _ = t.paired(controls, runs, cond, f"{best}|mirror", "soft|mirror", "gt_style")
    floor = t.mean_row(controls, [], cond, "gt_take", "gt_style")[0]
    return Effect(tuple(per), -1, BN2_LABELS[cond], rule="pairs", need=3, pairs=(m, se, n),
                  share=-m / (g[best] - floor), of=f"{{p}} % of {best}'s gap to the floor", unit="m/s")


def _zeggs_small() -> dict:
    return _driver_results("zeggs_synthetic/configs/small.toml")


def _beats_shuffled() -> list:
    seeds = _zeggs_small()["seeds"].values()
    b = [s["heldout_scripts"]["beat_alignment"] for s in seeds]
    d = [x["generated_vs_control"]["mean"] for x in b]
    real = [x["real_vs_control"]["mean"] for x in b]
    return [Effect(tuple(d), +1, share=float(np.mean(d) / np.mean(real)), of="{p} % of real motion's margin",
                   unit="BeatAlign")]


def _encoder_style() -> list:
    seeds = list(_zeggs_small()["seeds"].values())
    d = [s["heldout_scripts"]["leakage"]["contrasts"]["other_style - same_style_other_content"]["mean"] for s in seeds]
    p = [s["pooled"]["probe_pooled"]["style"] for s in seeds]
    share = np.mean([x["trained"] - x["random_init"] for x in p]) / np.mean(
        [x["raw_statistics"] - x["random_init"] for x in p])
    return [Effect(tuple(d), +1, share=float(share), of="probe at {p} % from random init to raw statistics",
                   unit="loss", digits=2, prefix="another style")]


def _frechet_heldout() -> list:
    r = [s["heldout_scripts"]["frechet_distance"] for s in _zeggs_small()["seeds"].values()]
    logs = [math.log(x["generated_vs_real"] / x["real_train_vs_real_test"]) for x in r]
    m, lo, hi = interval(logs)
    return [Effect(tuple(logs), -1, text=f"{math.exp(m):.2f}x [{math.exp(lo):.2f}, {math.exp(hi):.2f}] the real-vs-real floor "
                   "(geometric)")]


@functools.lru_cache(maxsize=None)
def _zc():
    return _module("zeggs_claims/tables.py", "_claims_zeggs_claims")


def _zc_docs(runs) -> list:
    docs = [_zc().load(r) for r in runs]
    if any(d is None for d in docs):
        raise FileNotFoundError(f"zeggs_claims: corrected-judge results missing for {runs}")
    return [d["results"] for d in docs]


def _zc_threshold(runs, name: str) -> float:
    """A registered threshold of the runs (their stamps' config, ``thresholds``): the same in every run."""
    return _zc()._threshold([(r, _zc().load(r)) for r in runs], name)


def _style_portrayal() -> list:
    sp = [d["claims"]["style_portrayal"] for d in _zc_docs(_zc().MAIN)]
    ratio = [x["ratio_to_gt"] for x in sp]
    share = np.mean([x["generated"]["mean"] - x["mm"]["mean"] for x in sp]) / np.mean(
        [x["gt"]["mean"] - x["mm"]["mean"] for x in sp])
    need = _zc_threshold(_zc().MAIN, "style_ratio")
    return [Effect(tuple(r - need for r in ratio), +1, rule="count", passed=tuple(x["holds"] for x in sp),
                   need=_zc().NEED, share=float(share), of="{p} % of the MM-GT gap",
                   text=f"accuracy {min(ratio):.2f}-{max(ratio):.2f}x GT's ({need:g} needed)")]


def _naturalness() -> list:
    re_ = [d["claims"]["realism"] for d in _zc_docs(_zc().MAIN)]
    g = [x["geometric_mean_ratio"] for x in re_]
    return [Effect(tuple(math.log(x) for x in g), -1, rule="count", passed=tuple(x["holds"] for x in re_),
                   need=_zc().NEED, text=f"Fréchet {min(g):.2f}-{max(g):.2f}x real other-script motion's "
                                         "(<= 1 needed)")]


def _beats_mm() -> list:
    ap = [d["claims"]["appropriateness"] for d in _zc_docs(_zc().MAIN)]
    d = [x["generated_minus_mm"]["mean"] for x in ap]
    share = np.mean(d) / np.mean([x["gt_minus_mm"]["mean"] for x in ap])
    return [Effect(tuple(d), +1, rule="count", passed=tuple(x["holds"] for x in ap), need=_zc().NEED,
                   share=float(share), of="{p} % of GT's margin", prefix="BeatAlign")]


def _beats_real_speech() -> list:
    docs = _zc_docs(_zc().MAIN)
    out = []
    for st in sorted(docs[0]["real_speech"]["styles"]):
        xs = [d["real_speech"]["styles"][st] for d in docs]
        d = [x["generated"]["mean"] - x["mm"]["mean"] for x in xs]
        out.append(Effect(tuple(d), +1, f"`{st}`", rule="count", passed=tuple(x["holds"] for x in xs),
                          need=_zc().NEED, unit=""))
    return out


def _zero_shot() -> list:
    out = []
    for style in ("sad", "tense"):
        runs = [r for r in _zc().ZERO_SHOT if f"_{style}_" in r]
        z = [d["claims"]["zero_shot"][style] for d in _zc_docs(runs)]
        need = _zc_threshold(runs, "zero_shot_ratio")
        out.append(Effect(tuple(x["ratio"] - need for x in z), +1, f"`{style}`", rule="count",
                          passed=tuple(x["holds"] for x in z), need=len(z),
                          text=f"accuracy <= {max(x['generated'] for x in z):.3f} (GT "
                               f"{min(x['gt'] for x in z):.2f})"))
    return out


BN1, BN2, SYN = "BN-1", "BN-2", "synthetic"

CLAIMS = [
    Claim("TGST", "the transfer moves a clip toward the exemplar's style", BN1, "tgst_bandai", lambda: [
        _bn1_gap(c, "soft", "content_as_is", "style_as_is", "style", -1, c) for c in ("intra", "inter")]),
    Claim("TGST", "the soft swap has the lowest style error of four (Tables 2-3)", BN1, "tgst_bandai",
          lambda: [_bn1_soft_vs_hard(c) for c in ("intra", "inter")]),
    Claim("TGST", "the content survives the transfer (below the style sample's)", BN1, "tgst_bandai", lambda: [
        _bn1_gap(c, "soft", "style_as_is", "content_as_is", "content", -1, c) for c in ("intra", "inter")]),
    Claim("TGST", "the style error measures style (Table 1)", BN1, "tgst_bandai",
          _bn1_table1, " inter, model-free"),
    Claim("TGST", "without L_identity the content error rises (Table 4)", BN1, "tgst_bandai",
          lambda: _ablation("identity", "content")),
    Claim("TGST", "without L_cyclic the content error rises (Table 4)", BN1, "tgst_bandai",
          lambda: _ablation("cyclic", "content")),
    Claim("TGST", "without L_structure the style error rises (Table 4)", BN1, "tgst_bandai",
          lambda: _ablation("structure", "style")),
    Claim("TGST", "without L_appearance the style error rises (Table 4)", BN1, "tgst_bandai",
          lambda: _ablation("appearance", "style")),
    Claim("TGST", "the content survives, judged against another take", BN2, "tgst_bandai2", lambda: [
        _bn2_relation("soft|mirror", "style_as_is", "gt_content", "style_as_is", c)
        for c in ("inter-mirror", "inter-other")]),
    Claim("TGST", "the style moves toward the target, against another take", BN2, "tgst_bandai2",
          lambda: [_bn2_relation("soft|mirror", "content_as_is", "gt_style", "content_as_is", c)
                   for c in ("inter-mirror", "inter-other")]),
    Claim("TGST", "soft swap lowest of four on style, against another take", BN2, "tgst_bandai2",
          lambda: [_bn2_soft_vs_next(c) for c in ("inter-mirror", "inter-other")]),
    Claim("TGST", "*not in the paper:* a constant-rate token path takes style", BN2,
          "tgst_bandai2", lambda: [_bn2_relation("coherent|mirror", "content_as_is", "gt_style", "content_as_is", c)
                                   for c in ("inter-mirror", "inter-other")]),
    Claim("ZeroEGGS", "gestures follow the beats, vs shuffled onsets (not MM)",
          SYN, "zeggs_synthetic", _beats_shuffled),
    Claim("ZeroEGGS", "gestures fit the speech better than mismatched motion (MM)", SYN, "zeggs_claims",
          _beats_mm),
    Claim("ZeroEGGS", "gestures fit real speech better than MM", "real speech", "zeggs_claims",
          _beats_real_speech, ","),
    Claim("ZeroEGGS", "the encoder reads style (diagnostic)",
          SYN, "zeggs_synthetic", _encoder_style),
    Claim("ZeroEGGS", "generated motion is as realistic as real (Fréchet)", SYN, "zeggs_synthetic",
          _frechet_heldout),
    Claim("ZeroEGGS", "generated motion is as natural as MM", SYN, "zeggs_claims", _naturalness),
    Claim("ZeroEGGS", "generated motion portrays the example's style", SYN, "zeggs_claims", _style_portrayal),
    Claim("ZeroEGGS", "a style left out of training is reproduced", SYN, "zeggs_claims",
          _zero_shot, ", left out:"),
]


def render() -> str:
    lines = ["| paper | claim | verdict | effect | data (its experiment), rule |", "|---|---|---|---|---|"]
    lines += [r for c in CLAIMS for r in rows(c)]
    return "\n".join(lines)


def block() -> str:
    """The README block: the table and how it was made (every results file read afresh)."""
    for cached in (_driver_results, _bn2_runs, _zc):
        cached.cache_clear()
    return (f"{START}\n{render()}\n\nGenerated from the experiments' stamped results files by "
            "`python -m experiments table claims` (rows and rule: `experiments/claims.py`).\n" + END)


def check() -> list[str]:
    """One line when README.md's claims table differs from what the results files give."""
    m = BLOCK.search(README.read_text())
    if m is None:
        return [f"{README}: no claims table ({START} ... {END})"]
    try:
        want = block()
    except (FileNotFoundError, DriverError) as e:
        return [f"{README}: the claims table's results are missing ({e})"]
    if m.group(0) != want:
        return [f"{README}: the claims table differs from its results (regenerate: python -m experiments table claims)"]
    return []


def update() -> int:
    text = README.read_text()
    if not BLOCK.search(text):
        raise ValueError(f"{README}: no {START} ... {END} markers")
    README.write_text(BLOCK.sub(lambda _: block(), text))
    print(f"claims: written to {README.relative_to(REPO)}")
    return 0
