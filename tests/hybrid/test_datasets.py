"""Fetching the measured data sets: download once (checked by SHA-256), then load offline.

The downloads here come from a local HTTP server, so the tests run without a network.
"""

import functools
import hashlib
import http.server
import socket
import threading

import numpy as np
import pytest

pytest.importorskip("pooch")

from physics.data import DataError, DataNotFoundError, load_preset  # noqa: E402
from physics.data import _fetch  # noqa: E402
from physics.data._fetch import DataSource, dataset_folder, download_source  # noqa: E402


@pytest.fixture()
def server(tmp_path):
    """Serve ``tmp_path / "site"`` on localhost; yields (site folder, base URL)."""
    site = tmp_path / "site"
    site.mkdir()
    handler = functools.partial(_Quiet, directory=str(site))
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield site, f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


def _source(site, base_url, files, digests=None):
    for name, text in files.items():
        (site / name).write_text(text)
    digests = digests or {n: hashlib.sha256(t.encode()).hexdigest() for n, t in files.items()}
    return DataSource("toy", base_url, digests, "a test")


def test_download_once_then_offline(server, tmp_path, monkeypatch):
    site, url = server
    source = _source(site, url, {"a.txt": "1,2\n", "b.txt": "3,4\n"})
    monkeypatch.setitem(_fetch.SOURCES, "toy", source)
    monkeypatch.setenv("HYST_DATA_DIR", str(tmp_path / "cache"))
    folder = dataset_folder("toy")
    assert folder == tmp_path / "cache" / "toy"
    assert (folder / "a.txt").read_text() == "1,2\n" and (folder / "b.txt").read_text() == "3,4\n"
    for f in site.iterdir():  # the source goes away: the cache is enough
        f.unlink()
    assert dataset_folder("toy", download=False) == folder


def test_checksum_mismatch_is_a_clear_error_and_keeps_no_file(server, tmp_path):
    site, url = server
    source = _source(site, url, {"a.txt": "tampered\n"}, {"a.txt": hashlib.sha256(b"original\n").hexdigest()})
    with pytest.raises(DataError, match="does not match its published SHA-256"):
        download_source(source, tmp_path / "cache")
    assert list((tmp_path / "cache").iterdir()) == []  # no partial or foreign file left


def test_no_network_says_where_to_put_the_files(tmp_path):
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    source = DataSource("toy", f"http://127.0.0.1:{port}", {"a.txt": "0" * 64}, "a test")
    with pytest.raises(DataNotFoundError, match=r"Put its files \(a\.txt\) in .*cache.* by hand"):
        download_source(source, tmp_path / "cache")


def test_a_damaged_file_in_a_cache_is_named(tmp_path, monkeypatch):
    folder = tmp_path / "toy"
    folder.mkdir()
    (folder / "a.txt").write_text("damaged")
    monkeypatch.setitem(_fetch.SOURCES, "toy", DataSource("toy", "http://127.0.0.1:9", {"a.txt": "0" * 64}, ""))
    monkeypatch.setenv("HYST_DATA_DIR", str(tmp_path))
    with pytest.raises(DataError, match=r"a\.txt has SHA-256 .* Delete it"):
        dataset_folder("toy")


def test_unknown_data_set_lists_the_known_ones():
    with pytest.raises(DataError, match="Must be one of.*catheter_2023"):
        dataset_folder("catheter_2024")


def test_shared_folder_is_a_prefilled_cache_with_the_published_files():
    if not all((_fetch.SHARED / s.name).is_dir() for s in _fetch.SOURCES.values()):
        pytest.skip(f"the shared data folder {_fetch.SHARED} is absent; nothing to check offline")
    from hybrid.datasets import fetch_boucwen_benchmark, fetch_catheter_2023, fetch_niti_frequency_trials

    for name in _fetch.SOURCES:
        assert dataset_folder(name, download=False) == _fetch.SHARED / name  # every SHA-256 matched
    bw = fetch_boucwen_benchmark()
    assert [t.n for t in bw.train] == [40960] and [t.n for t in bw.test] == [8192, 153000]
    assert np.median(np.diff(bw.train[0].time)) == pytest.approx(1 / 750)
    assert len(fetch_catheter_2023().train) == 5
    assert len(fetch_niti_frequency_trials().test) == 3
    assert load_preset("boucwen_benchmark", rate_hz=None).test[0].meta["part"] == "multisine"
    # each data set's own rate by default: the benchmark's raw 750 Hz (25 Hz would alias its band)
    assert [t.n for t in load_preset("boucwen_benchmark").train] == [40960]
    assert np.median(np.diff(load_preset("catheter_2023:reverse").train[0].time)) == pytest.approx(1 / 25)
    with pytest.raises(DataError, match="would alias"):
        load_preset("boucwen_benchmark", rate_hz=25.0)


def test_every_data_set_has_a_default_rate_and_a_bad_one_is_named():
    from physics.data._presets import DEFAULT_RATES, PRESETS

    assert set(DEFAULT_RATES) == set(PRESETS)
    with pytest.raises(DataError, match="rate_hz must be a rate in Hz, None .* or 'default'. Got 'native'"):
        load_preset("catheter_2023", rate_hz="native")
