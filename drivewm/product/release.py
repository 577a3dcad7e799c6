"""The weights drivewm ships: export of a ``drivewm worldmodel train`` run, and where they are found.

``export_run(RUN, DIR)`` writes ``DIR/tokenizer``, ``DIR/text2world`` and ``DIR/multiview`` (and
``DIR/transfer`` when the run has a ``transfer`` folder) as model folders with fp16 weights (loaders
cast them to the network's dtype), the diffusion models pointing at the tokenizer by the relative
path ``../tokenizer`` and the transfer model at its Text2World parent by ``../text2world``
(resolved against the model folder, so the package works wherever it is installed), plus
``DIR/MANIFEST.json`` (sha256 and size of every file, training steps and seconds of every stage),
which the model card (MODEL_CARD.md) quotes. ``replace_shipped`` puts a fine-tune in place of an
installed folder; where the installed folders are (``shipped:KIND``) is drivewm.model_folders'.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import torch

from drivewm.atomic import write_json
from drivewm.errors import DrivewmError
from drivewm.model_folders import SHIPPED_KINDS, WEIGHTS_DIR, file_sha256, resolve_model_folder, resolve_reference
from drivewm.paths import replacing_shipped
from drivewm.product.model_card import write_model_card
from drivewm.train.checkpoint import load_model_folder, save_model_folder
from drivewm.train.record import training_record

#: Run folders an export may lack (a run without paired drives trains no transfer model).
OPTIONAL_FOLDERS = ("transfer", "judge")
#: The model types a shipped folder may hold.
MODEL_TYPES = ("drivewm-tokenizer", "text2world", "multiview", "transfer", "judge")
MAX_FILE_BYTES = 16 * 1000 * 1000
MAX_TOTAL_BYTES = 40 * 1000 * 1000


def export_folder(src: Path, dst: Path) -> dict:
    """Copy a model folder with fp16 weights and a package-relative tokenizer path; returns its training record."""
    info, state = load_model_folder(src, MODEL_TYPES)
    half = {k: v.half() if v.is_floating_point() else v for k, v in state.items()}
    extra = folder_extra(info)
    if "latent" in extra and extra["latent"].get("tokenizer"):
        extra["latent"] = {**extra["latent"], "tokenizer": "../tokenizer"}
    if extra.get("parent"):  # a transfer model's Text2World parent ships beside it
        extra["parent"] = "../text2world"
    save_model_folder(dst, info["model_type"], info["config"], half, extra)
    return training_record(src)


def folder_extra(info: dict) -> dict:
    """What a model folder's config.json holds beside its type, version and config (latent settings,
    parent, digests), to save again with new weights."""
    return {k: v for k, v in info.items() if k not in ("model_type", "drivewm_version", "config")}


def interpolate_folders(
    base: str | Path, tuned: str | Path, alpha: float, out: str | Path, config_from: str = "tuned"
) -> Path:
    """Write the model folder ``out`` whose weights are ``(1 - alpha) * base + alpha * tuned`` (in float32):
    a fine-tune pulled back towards the model it started from, which keeps more of what the fine-tune's
    data lacked (WiSE-FT, Wortsman et al. 2022). Both folders must be one model type with the same
    tensors; ``config_from`` ("base" or "tuned") names the folder whose config and latent settings
    (rig, tokenizer, speed) the result keeps. Returns ``out``."""
    if not 0.0 <= alpha <= 1.0:
        raise DrivewmError(f"interpolate: alpha must be in [0, 1] (0 = base, 1 = tuned), got {alpha}")
    if config_from not in ("base", "tuned"):
        raise DrivewmError(f"interpolate: config_from must be 'base' or 'tuned', got {config_from!r}")
    (info_a, a), (info_b, b) = load_model_folder(base, MODEL_TYPES), load_model_folder(tuned, MODEL_TYPES)
    if info_a["model_type"] != info_b["model_type"]:
        raise DrivewmError(f"interpolate: {base} is a {info_a['model_type']} model, {tuned} a {info_b['model_type']}")
    differ = sorted(k for k in a.keys() | b.keys() if k not in a or k not in b or a[k].shape != b[k].shape)
    if differ:
        raise DrivewmError(
            f"interpolate: {base} and {tuned} differ in structure ({len(differ)} tensors, e.g. {differ[0]})"
        )
    unequal = [k for k in a if not a[k].is_floating_point() and not torch.equal(a[k], b[k])]
    if unequal:
        raise DrivewmError(f"interpolate: non-float tensors differ ({unequal[0]}); these models do not mix")
    state = {k: torch.lerp(a[k].float(), b[k].float(), alpha) if a[k].is_floating_point() else a[k] for k in a}
    info = info_a if config_from == "base" else info_b
    extra = folder_extra(info)
    tok = (extra.get("latent") or {}).get("tokenizer")
    if tok:  # a shipped folder's ../tokenizer, a run's own: the folder itself, recorded again for out
        folder = resolve_model_folder(base if config_from == "base" else tuned)
        extra["latent"] = {**extra["latent"], "tokenizer": str(resolve_reference(tok, folder))}
    save_model_folder(out, info["model_type"], info["config"], state, extra)
    return Path(out)


def export_run(run: str | Path, out: str | Path, notes: str = "") -> list[Path]:
    """Export the model folders of ``run`` (three, or four with a transfer model) into ``out``, write
    the manifest and the model card (drivewm.product.model_card, with ``notes`` as its last section);
    returns the files."""
    run, out = Path(run), Path(out)
    kinds = [kind for kind in SHIPPED_KINDS if kind not in OPTIONAL_FOLDERS or (run / kind).is_dir()]
    records = {kind: export_folder(run / kind, out / kind) for kind in kinds}
    files = folder_files(out, {kind: out / kind for kind in kinds})
    manifest = {"files": manifest_files(out, files), "training": records}
    write_json(out / "MANIFEST.json", manifest)
    return [*files, out / "MANIFEST.json", write_model_card(run, out, manifest, notes)]


def folder_files(root: Path, folders: dict[str, Path]) -> list[Path]:
    """The files of the shipped ``folders`` (name -> where they are now), refused beyond the package
    limits (16 MB a file, 40 MB in all) before anything is written over."""
    files = sorted(p for folder in folders.values() for p in folder.iterdir() if p.is_file())
    sizes = {f"{p.parent.name}/{p.name}": p.stat().st_size for p in files}
    if max(sizes.values(), default=0) > MAX_FILE_BYTES or sum(sizes.values()) > MAX_TOTAL_BYTES:
        raise DrivewmError(f"{root}: shipped weights must be <= 16 MB a file, 40 MB in all; got {sizes}")
    return files


def manifest_files(root: Path, files: list[Path]) -> dict:
    """``MANIFEST.json``'s ``files``: path under ``root`` -> sha256 and bytes."""
    return {str(p.relative_to(root)): {"sha256": file_sha256(p), "bytes": p.stat().st_size} for p in files}


def replace_shipped(kind: str, src: str | Path, root: Path = WEIGHTS_DIR, device: str = "cpu", note: str = "") -> dict:
    """Replace the shipped folder ``kind`` by ``src``, a fine-tune of it (``drivewm posttrain --init
    shipped:multiview``), exported as :func:`export_run` exports a run's folders; rewrites
    ``MANIFEST.json``: every file's sha256 and bytes, and ``kind``'s training record with the fine-tune's
    steps and seconds added to the folder's own and listed under ``fine_tunes`` (a kind not shipped yet
    is shipped with ``src``'s record as its own). Returns the manifest;
    the model card's figures and sha256 are the caller's to update (tests/test_shipped_weights.py checks
    the sha256). ``device``: what the fine-tune ran on; a GPU's seconds are listed as ``gpu_seconds``,
    apart from the CPU seconds of ``train_seconds``. ``note``: what the record alone does not say (e.g.
    that the folder is a fine-tune mixed with the shipped one, drivewm.product.release.interpolate_folders)."""
    with replacing_shipped():
        return _replace_shipped(kind, Path(src), root, device, note)


def _replace_shipped(kind: str, src: Path, root: Path, device: str, note: str) -> dict:
    """:func:`replace_shipped`, its writes let into the shipped weights."""
    if kind not in SHIPPED_KINDS:
        raise DrivewmError(f"no shipped model {kind!r}: drivewm ships {', '.join(SHIPPED_KINDS)}")
    manifest = check_manifest(root)  # never build on a manifest that no longer matches its files
    record = training_record(Path(src))
    if not record:
        raise DrivewmError(
            f"{src}: no train_state.pt or metrics.jsonl, so no record of the fine-tune's steps to ship with it"
        )
    if device != "cpu":
        record["device"] = device
    if note:
        record["note"] = note
    before = manifest["training"].get(kind)  # None: a kind shipped the first time (the judge)
    staged = root / f".{kind}.new"  # exported beside the shipped folder, which is replaced only once it fits
    shipped = {n: root / n for n in SHIPPED_KINDS if (root / n).is_dir()}
    shutil.rmtree(staged, ignore_errors=True)
    try:
        export_folder(Path(src), staged)
        folder_files(root, {**shipped, kind: staged})
    except BaseException:
        shutil.rmtree(staged, ignore_errors=True)
        raise
    shutil.rmtree(root / kind, ignore_errors=True)
    staged.rename(root / kind)
    manifest["files"] = manifest_files(root, folder_files(root, {**shipped, kind: root / kind}))
    manifest["training"][kind] = record if before is None else _add_fine_tune(before, record, device)
    write_json(root / "MANIFEST.json", manifest)
    return manifest


def _add_fine_tune(before: dict, record: dict, device: str) -> dict:
    """A shipped folder's training record ``before`` with the fine-tune's ``record`` added."""
    clock = "train_seconds" if device == "cpu" else "gpu_seconds"
    seconds = [before.get(clock, 0.0 if clock == "gpu_seconds" else None), record["train_seconds"]]
    return {
        **before,
        "steps": before["steps"] + record["steps"],
        clock: None if None in seconds else sum(seconds),
        "fine_tunes": [*before.get("fine_tunes", []), record],
    }


def check_manifest(root: Path = WEIGHTS_DIR) -> dict:
    """The shipped manifest, after checking every file's sha256 against it (DrivewmError on a mismatch)."""
    manifest = json.loads((root / "MANIFEST.json").read_text())
    for name, entry in manifest["files"].items():
        if file_sha256(root / name) != entry["sha256"]:
            raise DrivewmError(f"{root / name}: sha256 differs from MANIFEST.json (a corrupt or replaced file)")
    return manifest


__all__ = ["check_manifest", "export_run", "interpolate_folders", "replace_shipped"]
