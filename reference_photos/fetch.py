"""Fetch the reference photos of manifest.json from their sources, each checked against its sha256.

    .venv/bin/python reference_photos/fetch.py                 # into reference_photos/ (git-ignored)
    .venv/bin/python reference_photos/fetch.py --to DIR 01 06  # some photos, into DIR
    BOKEHFIT_REFERENCE_DIR=DIR .venv/bin/python -m pytest ...  # then the tests find them there

A photo is downloaded from its ``url`` in the manifest (a fixed commit of the public repository
that ships it) to a temporary name beside its place, hashed, and kept only when its SHA-256 is
the manifest's: a changed or damaged download is refused and removed, never kept under the
photo's name. A photo already there with the right hash is not fetched again; one with another
hash is refused (move it away first). Photos without a ``url`` are named with their source, to
be fetched by hand. Exit code 0 when every photo asked for is in place, 1 otherwise.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import tempfile
import urllib.request
from pathlib import Path

MANIFEST = Path(__file__).resolve().with_name("manifest.json")
#: Seconds a download may stall before it is given up.
TIMEOUT_S = 60
#: No reference photo is larger than this (bytes): a source that sends more is refused.
MAX_BYTES = 64 * 1024 * 1024
_CHUNK = 1 << 20


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(_CHUNK), b""):
            digest.update(block)
    return digest.hexdigest()


def download(url: str, target: Path, sha256: str, *, opener=urllib.request.urlopen) -> None:
    """Download ``url`` to ``target`` through a temporary file, keeping it only if its SHA-256 is ``sha256``.

    Raises ``ValueError`` (the temporary file removed) for a download of another hash or past
    :data:`MAX_BYTES`; ``OSError`` for a failed one.
    """
    if not url.startswith(("https://", "file:")):
        raise ValueError(f"refusing {url!r}: only https:// (or a local file: URL) is fetched")
    handle, temporary = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
    try:
        digest, size = hashlib.sha256(), 0
        with os.fdopen(handle, "wb") as out, opener(url, timeout=TIMEOUT_S) as response:
            for block in iter(lambda: response.read(_CHUNK), b""):
                size += len(block)
                if size > MAX_BYTES:
                    raise ValueError(f"{url} sends more than {MAX_BYTES} bytes: not a reference photo")
                digest.update(block)
                out.write(block)
        if digest.hexdigest() != sha256:
            raise ValueError(f"{url} gave sha256 {digest.hexdigest()[:16]}…, the manifest says {sha256[:16]}…: "
                             "the source changed or the download is damaged; nothing kept")
        os.replace(temporary, target)
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)


def fetch(photos: list[dict], folder: Path, *, opener=urllib.request.urlopen, say=print) -> int:
    """Put each photo of ``photos`` (manifest entries) in ``folder``; returns how many are not in place."""
    missing = 0
    for photo in photos:
        target = folder / photo["file"]
        if target.exists():
            if sha256_of(target) == photo["sha256"]:
                say(f"ok       {photo['file']} (already there)")
                continue
            say(f"refused  {photo['file']}: a file of another sha256 is there; move it away and run again")
            missing += 1
            continue
        url = photo.get("url")
        if not url:
            say(f"by hand  {photo['file']}: no download address; its source: {photo['source']}")
            missing += 1
            continue
        try:
            download(url, target, photo["sha256"], opener=opener)
        except (OSError, ValueError) as error:
            say(f"failed   {photo['file']}: {error}")
            missing += 1
            continue
        say(f"fetched  {photo['file']} (sha256 checked)")
    return missing


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("photos", nargs="*", metavar="NAME",
                        help="photos to fetch: file names or their number prefixes (01, 06, ...); default all")
    parser.add_argument("--to", type=Path, default=MANIFEST.parent, metavar="DIR",
                        help="folder to put them in (default: reference_photos/)")
    parser.add_argument("--manifest", type=Path, default=MANIFEST, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    photos = json.loads(args.manifest.read_text(encoding="utf-8"))["photos"]
    if args.photos:
        chosen = [p for p in photos if any(p["file"] == name or p["file"].startswith(f"{name}_") for name in args.photos)]
        unknown = [name for name in args.photos
                   if not any(p["file"] == name or p["file"].startswith(f"{name}_") for p in photos)]
        if unknown:
            parser.error(f"no photo of the manifest is named {', '.join(unknown)}")
        photos = chosen
    args.to.mkdir(parents=True, exist_ok=True)
    missing = fetch(photos, args.to)
    print(f"{len(photos) - missing} of {len(photos)} photos in {args.to}")
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
