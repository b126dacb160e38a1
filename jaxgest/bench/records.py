"""The benchmark's JSON: one record per (case, implementation) -- the docs/design.md §8 fields plus the ones the
harness adds -- and the ``--json`` document around them (machine info, ratios, failures); their validation.
The harness (:mod:`jaxgest.bench.harness`) writes them, :mod:`jaxgest.bench.suite` validates a document before
writing it.
"""

from __future__ import annotations

from jaxgest.runtime.provenance import STAMP_KEYS

# The docs/design.md §8 record (key -> allowed JSON types), and the extra fields the harness adds.
RECORD_FIELDS: dict[str, tuple] = {
    "case": (str,),
    "impl": (str,),
    "batch": (int,),
    "frames": (int,),
    "per_pose_us": (float,),
    "compile_s": (float, type(None)),
    "repeats": (int,),
    "min_us": (float,),
    "median_us": (float,),
}
EXTRA_FIELDS: dict[str, tuple] = {
    "trace_s": (float, type(None)),
    "lower_s": (float, type(None)),
    "inner": (int,),
    "poses": (int,),
    "per_frame_us": (float,),
    "cpu_median_us": (float,),
    "peak_rss_mb": (float, type(None)),
    "peak_mem_mb": (float, type(None)),
    "max_abs_diff": (float, type(None)),
    "group": (str,),
    "note": (str,),
    "interleaved": (bool,),
    "flops": (float, type(None)),
    "bytes": (float, type(None)),
    "floor_bound": (str, type(None)),
    "floor_fraction": (float, type(None)),
    "xla_flops": (float, type(None)),
    "xla_bytes_accessed": (float, type(None)),
    "reference": (str, type(None)),
}
# The JSON document written by ``--json``.
DOCUMENT_FIELDS: dict[str, tuple] = {
    "machine": (dict,),
    "quick": (bool,),
    "wall_s": (float,),
    "records": (list,),
    "ratios": (dict,),
    "failures": (list,),
}


def _check_fields(obj: dict, fields: dict, required: bool, what: str) -> None:
    for key, types in fields.items():
        if key not in obj:
            if required:
                raise ValueError(f"{what} misses {key!r}")
            continue
        value = obj[key]
        # bool is an int subclass in Python but not a number in the schema.
        if not isinstance(value, types) or (isinstance(value, bool) and bool not in types):
            names = "/".join("null" if t is type(None) else t.__name__ for t in types)
            raise ValueError(f"{what} field {key!r} is {type(value).__name__}, expected {names}")


def validate_record(rec: dict) -> None:
    """Raise ValueError when a record does not follow the docs/design.md §8 schema (plus the extra fields)."""
    what = f"record {rec.get('case')}/{rec.get('impl')}"
    _check_fields(rec, RECORD_FIELDS, True, what)
    _check_fields(rec, EXTRA_FIELDS, False, what)
    if not (0 < rec["min_us"] <= rec["median_us"]) or rec["per_pose_us"] <= 0:
        raise ValueError(f"{what}: times are inconsistent (min {rec['min_us']}, median {rec['median_us']})")
    if rec["batch"] < 1 or rec["frames"] < 1 or rec["repeats"] < 1:
        raise ValueError(f"{what}: batch, frames and repeats must be positive")
    if rec["compile_s"] is not None and rec["compile_s"] < 0:
        raise ValueError(f"{what}: negative compile_s")


def validate_document(doc: dict) -> None:
    """Raise ValueError when a ``--json`` document (machine info + records) is malformed."""
    if not isinstance(doc, dict):
        raise ValueError(f"document is {type(doc).__name__}, expected an object")
    _check_fields(doc, DOCUMENT_FIELDS, True, "document")
    for rec in doc["records"]:
        validate_record(rec)
    for key in ("cpu", "cores", "jax", "jaxlib", "xla_flags"):
        if key not in doc["machine"]:
            raise ValueError(f"document machine info misses {key!r}")
    # ``stamp`` (jaxgest.runtime.provenance.stamp: commit, dirty, version, the cases and settings run as its
    # config, the command); the machine (CPU, XLA flags, threads) is ``machine``. Files written before the
    # stamp existed have none.
    if "stamp" in doc:
        if not isinstance(doc["stamp"], dict):
            raise ValueError(f"document field 'stamp' is {type(doc['stamp']).__name__}, expected dict")
        for key in STAMP_KEYS:
            if key not in doc["stamp"]:
                raise ValueError(f"document stamp misses {key!r}")
