"""Fingerprints of the shared simulated test data (tests/conftest.py: sim_log_dir, sim_clip_dir),
so a change to the reader, the curation stage or the simulator that alters what the lead's
training runs read is caught: the MCAP logs, and per shard member the sha256 of the bytes (clip
JSON with ``source_log`` reduced to its file name, since the cache folder is in the path).

    python tests/curate/golden_clips.py LOGDIR CLIPDIR   # rewrite data/shared_clips_golden.json
"""

from __future__ import annotations

import hashlib
import json
import sys
import tarfile
from pathlib import Path

GOLDEN = Path(__file__).parent / "data" / "shared_clips_golden.json"


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _member_bytes(name: str, data: bytes) -> bytes:
    if not name.endswith(".json"):
        return data
    meta = json.loads(data)
    meta["source_log"] = Path(meta["source_log"]).name
    return json.dumps(meta, sort_keys=True).encode()


def fingerprints(log_dir: Path, clip_dir: Path) -> dict[str, str]:
    """{"logs/NAME.mcap": sha, "SHARD/MEMBER": sha, ...} of a log folder and its curated clips."""
    out = {f"logs/{p.name}": _sha(p.read_bytes()) for p in sorted(Path(log_dir).glob("*.mcap"))}
    for shard in sorted(Path(clip_dir).glob("*.tar")):
        with tarfile.open(shard) as tar:
            for m in tar:
                out[f"{shard.name}/{m.name}"] = _sha(_member_bytes(m.name, tar.extractfile(m).read()))
    return out


if __name__ == "__main__":
    GOLDEN.write_text(json.dumps(fingerprints(Path(sys.argv[1]), Path(sys.argv[2])), indent=1, sort_keys=True) + "\n")
    print(GOLDEN)
