"""The measured data sets: where they are published, their checksums, and where they are kept.

A data set's folder is found, in this order, in ``$HYST_DATA_DIR/<name>`` (a folder the
user chose; missing files are downloaded into it), in ``<repo>/../shared/data/<name>`` (a
pre-filled cache beside a clone, used only when complete), and in the user cache folder
(``pooch.os_cache("hysteresis-hybrid")``), where the files are downloaded on first use.
Every file is checked by SHA-256; a download that does not match is removed and reported,
so a folder never holds a partial or foreign file under a published name.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

from ._errors import DataError, DataNotFoundError

__all__ = ["DataSource", "SOURCES", "dataset_folder", "download_source", "user_cache"]

ENV_VAR = "HYST_DATA_DIR"
#: The shared data folder beside a clone: a pre-filled cache, so tests run offline.
SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data"


@dataclass(frozen=True)
class DataSource:
    """A published data set: ``files`` (name -> SHA-256) under ``base_url``."""

    name: str
    base_url: str
    files: dict[str, str]
    citation: str

    def url(self, file: str) -> str:
        return f"{self.base_url.rstrip('/')}/{file}"


_SEED = "https://github.com/wy-yuan/hysteresis-fnn-lstm/raw/2277c2f/tendon_data"
SOURCES: dict[str, DataSource] = {s.name: s for s in (
    DataSource("catheter_2023", f"{_SEED}/20230928/all_data", {
        "data_1_1.txt": "d3f32271e32143708373a56894009cd392361157f422f84d900c6c83f5be453b",
        "data_1_2.txt": "48fa4255c878874126acdced2d07a913802c20090bde44c5a66608eff602c558",
        "data_1_3.txt": "0ebfb2e9d66c27fcbcc653e8a9b336fd1d9cd00b70c5ecb67d282a5981557054",
        "data_1_4.txt": "271be0893348e43db54e748eb72d982dc9266a7f9e3c0a48917d480e4039fbf8",
        "data_1_5.txt": "e45ed9ed3e44a4ca3559ef1bac6a00e6854c9cf9a12cefb6cee9d7cb4b9b7d74",
        "data_2_1.txt": "3a4a22e019f399cfd54671cef6a799b3fb77c4fa8a63ebd100e16b7822de99ab",
        "data_2_2.txt": "094f695e3b88296d7ccea398ef45901c1db6a8d34a9541bd514ab4e0acc8a10d",
        "data_2_3.txt": "cd420a8437b37e502a53ad6847ec90ac6a12a1fd6f7d75c3c08a02516bda2121",
        "data_2_4.txt": "dd6e8b6dcf3b2c2ddf5f7d2df4a94e747c743dbb468f9f51ce1ac5b0e780d006",
        "data_2_5.txt": "6b9384ee6a42e43e07db0a8c27437f327500d189e7ee97c292920bc2e202dc1b",
    }, "Wang et al., tendon-driven cardiac catheter (github.com/wy-yuan/hysteresis-fnn-lstm)"),
    DataSource("niti_frequency_trials", f"{_SEED}/Frequency_Trials", {
        "Data_x2_09252023.mat": "23668b0bb9d979ed59551837da3b3bd8bee79ffe560b538ecbeaeb9d295bd5bc",
        "Random_data.mat": "81bb564edf0230183e3b9f75b75fe9498390abf1c2636a900c03003c4996a120",
        "f001_data_2.mat": "0ccd95263464ece29a071308fa338940671020b29d6f7ee8fbe4e75584d8dd70",
        "f002_data_2.mat": "1250338ea7eac9bc9f9a5be6badfc23a1fdf629d58e84bf222d3c13a1819f98d",
        "f010_data.mat": "c9400d2491f60faa3b874999164412b02166c983b9ba8570326a33aed24a3f10",
        "f015_data.mat": "f899d81e4ad9cf92c3fe527b601e4ab0da10bb0e451292adc9870544af3ab942",
        "f015_data_2.mat": "fac077bd61e27dbdf04fac49c51202b6776b59412ca8bf9c4dc07c4bb45d65de",
        "f020_data.mat": "37a95f42823abeb269c4aeb7283ace816e7d65a08fdac1ad7b0cff82a5410395",
        "f030_data.mat": "3177a506d8b528a7238e5fe11b3e51693a7181c354c211db7a3a621b4c6d925c",
    }, "Wang et al., NiTi-backbone robot (github.com/wy-yuan/hysteresis-fnn-lstm)"),
    DataSource("boucwen_benchmark", "https://github.com/preston1000/EHH/raw/"
               "cee58ac9e157b5d2e1e1df8dd64b660b070c05bb/data", {
                   "bouc-wen.mat": "f75007fab94706811b15412b1c08a511196ce11201a2c074ebfab55d26d94bd3",
               }, "Noel and Schoukens, Bouc-Wen benchmark (2016), copy in github.com/preston1000/EHH"),
)}

#: Files already checked in this process (path -> size, mtime): a folder is hashed once.
_CHECKED: dict[Path, tuple[int, float]] = {}


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _check_file(path: Path, expected: str) -> None:
    stat = path.stat()
    if _CHECKED.get(path) == (stat.st_size, stat.st_mtime):
        return
    found = sha256(path)
    if found != expected:
        raise DataError(f"{path} has SHA-256 {found[:12]}..., not the published file's {expected[:12]}...: "
                        "it is damaged or another file. Delete it and load the data set again to download it.")
    _CHECKED[path] = (stat.st_size, stat.st_mtime)


def _complete(folder: Path, source: DataSource) -> bool:
    return folder.is_dir() and all((folder / f).is_file() for f in source.files)


def user_cache() -> Path:
    """The per-user cache folder (``pooch.os_cache``)."""
    import pooch

    return Path(pooch.os_cache("hysteresis-hybrid"))


def _candidates() -> list[Path]:
    env = os.environ.get(ENV_VAR)
    if env:
        return [Path(env).expanduser()]
    return [SHARED, user_cache()]


def dataset_folder(name: str, download: bool = True) -> Path:
    """The folder holding data set ``name`` with every file checked, downloading what is missing.

    Raises
    ------
    DataError
        Unknown name, or a file whose SHA-256 is not the published one.
    DataNotFoundError
        Files missing and ``download=False`` or the download failed (no network).
    """
    if name not in SOURCES:
        raise DataError(f"unknown data set {name!r}. Must be one of {sorted(SOURCES)}.")
    source = SOURCES[name]
    places = _candidates()
    folder = next((p / name for p in places if _complete(p / name, source)), places[-1] / name)
    if not _complete(folder, source):
        if not download:
            raise DataNotFoundError(_by_hand(source, folder, "it is not downloaded yet"))
        download_source(source, folder)
    for file, digest in source.files.items():
        _check_file(folder / file, digest)
    return folder


def download_source(source: DataSource, folder: Path) -> None:
    """Download the files of ``source`` missing from ``folder`` (checked by SHA-256, atomically)."""
    import pooch

    folder.mkdir(parents=True, exist_ok=True)
    for file, digest in source.files.items():
        if (folder / file).is_file():
            continue
        try:  # pooch writes to a temporary file and moves it in place only when the hash matches
            pooch.retrieve(source.url(file), known_hash=f"sha256:{digest}", fname=file, path=folder,
                           progressbar=False)
        except ValueError as exc:  # hash mismatch: pooch has removed the download
            raise DataError(f"the download of {source.url(file)} does not match its published SHA-256 "
                            f"({exc}); nothing was kept. Try again later, or put the file in {folder} by hand."
                            ) from None
        except Exception as exc:  # noqa: BLE001 - requests' errors, OSError: no network, HTTP 404, ...
            raise DataNotFoundError(_by_hand(source, folder, f"the download of {source.url(file)} failed "
                                             f"({type(exc).__name__}: {exc})")) from None
        _CHECKED[folder / file] = ((folder / file).stat().st_size, (folder / file).stat().st_mtime)



def _by_hand(source: DataSource, folder: Path, why: str) -> str:
    return (f"data set {source.name!r} is not available: {why}. Put its files ({', '.join(source.files)}) "
            f"in {folder} by hand (from {source.base_url}), or set {ENV_VAR} to a folder that holds "
            f"{source.name}/.")
