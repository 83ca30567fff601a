"""``reference_photos/fetch.py``: a photo is kept only with the manifest's sha256 (local ``file:`` URLs, no network)."""

from __future__ import annotations

import hashlib
import importlib.util
import json
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "reference_photos" / "fetch.py"


@pytest.fixture(scope="module")
def fetch():
    spec = importlib.util.spec_from_file_location("fetch_reference_photos", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def entry(tmp_path: Path, name: str, data: bytes, *, sha256: str | None = None, url: bool = True) -> dict:
    source = tmp_path / "source" / name
    source.parent.mkdir(exist_ok=True)
    source.write_bytes(data)
    photo = {"file": name, "sha256": sha256 or hashlib.sha256(data).hexdigest(), "source": f"a test source of {name}"}
    if url:
        photo["url"] = source.as_uri()
    return photo


def test_a_photo_with_the_manifests_hash_is_kept(fetch, tmp_path):
    photo = entry(tmp_path, "01_good.jpg", b"the photo's bytes")
    (tmp_path / "to").mkdir()
    lines = []
    assert fetch.fetch([photo], tmp_path / "to", say=lines.append) == 0
    assert (tmp_path / "to" / "01_good.jpg").read_bytes() == b"the photo's bytes"
    assert lines[0].startswith("fetched") and "sha256 checked" in lines[0]
    assert fetch.fetch([photo], tmp_path / "to", say=lines.append) == 0 and "already there" in lines[-1]


def test_a_download_of_another_hash_is_refused_and_nothing_is_left(fetch, tmp_path):
    photo = entry(tmp_path, "02_changed.jpg", b"the source changed", sha256=hashlib.sha256(b"the original").hexdigest())
    (tmp_path / "to").mkdir()
    lines = []
    assert fetch.fetch([photo], tmp_path / "to", say=lines.append) == 1
    assert "failed" in lines[0] and "nothing kept" in lines[0]
    assert list((tmp_path / "to").iterdir()) == [], "no photo and no temporary file left"


def test_a_file_of_another_hash_in_place_is_not_overwritten(fetch, tmp_path):
    photo = entry(tmp_path, "03_there.jpg", b"the right bytes")
    (tmp_path / "to").mkdir()
    (tmp_path / "to" / "03_there.jpg").write_bytes(b"someone's own file")
    lines = []
    assert fetch.fetch([photo], tmp_path / "to", say=lines.append) == 1
    assert lines[0].startswith("refused")
    assert (tmp_path / "to" / "03_there.jpg").read_bytes() == b"someone's own file"


def test_only_https_is_fetched_and_a_photo_without_address_is_named_with_its_source(fetch, tmp_path):
    with pytest.raises(ValueError, match="only https://"):
        fetch.download("http://example.org/a.jpg", tmp_path / "a.jpg", "0" * 64)
    lines = []
    assert fetch.fetch([entry(tmp_path, "04_by_hand.jpg", b"x", url=False)], tmp_path, say=lines.append) == 1
    assert lines[0].startswith("by hand") and "a test source of 04_by_hand.jpg" in lines[0]


def test_main_fetches_the_photos_named_by_number(fetch, tmp_path, capsys):
    photos = [entry(tmp_path, "05_a.jpg", b"five"), entry(tmp_path, "06_b.jpg", b"six")]
    manifest = tmp_path / "manifest.json"
    manifest.write_text(json.dumps({"about": "", "photos": photos}))
    assert fetch.main(["--manifest", str(manifest), "--to", str(tmp_path / "to"), "06"]) == 0
    assert [p.name for p in (tmp_path / "to").iterdir()] == ["06_b.jpg"]
    assert "1 of 1 photos" in capsys.readouterr().out


def test_every_url_of_the_real_manifest_is_https_at_a_fixed_commit(fetch):
    photos = json.loads(fetch.MANIFEST.read_text(encoding="utf-8"))["photos"]
    urls = [p["url"] for p in photos if p.get("url")]
    assert urls, "the manifest gives no download address"
    for url in urls:
        assert url.startswith("https://raw.githubusercontent.com/")
        assert any(len(part) == 40 and all(c in "0123456789abcdef" for c in part) for part in url.split("/")), url
