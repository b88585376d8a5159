"""The measured data sets, fetched in the manner of ``sklearn.datasets.fetch_*``.

Each is downloaded from its public source on first use, checked by SHA-256 and kept in
the user cache folder (``$HYST_DATA_DIR`` overrides it; a ``shared/data`` folder beside a
clone is used as a pre-filled cache), then loaded offline.

>>> from hybrid.datasets import fetch_catheter_2023
>>> split = fetch_catheter_2023()  # doctest: +SKIP
>>> len(split.train), len(split.test)  # doctest: +SKIP
(5, 5)
"""

from __future__ import annotations

from physics.data import SOURCES, DataSplit, dataset_folder, load_preset, user_cache

__all__ = ["fetch_catheter_2023", "fetch_niti_frequency_trials", "fetch_boucwen_benchmark",
           "dataset_folder", "user_cache", "SOURCES"]


def fetch_catheter_2023(rate_hz: float | None | str = "default", input: str | None = None) -> DataSplit:  # noqa: A002
    """The seed paper's cardiac catheter: set 1 (train) and set 2 (test), ``load_preset("catheter_2023")``."""
    return load_preset("catheter_2023", rate_hz=rate_hz, input=input)


def fetch_niti_frequency_trials(rate_hz: float | None | str = "default", input: str | None = None) -> DataSplit:  # noqa: A002
    """The seed paper's NiTi robot (tension -> tip angle by default), ``load_preset("niti_frequency_trials")``."""
    return load_preset("niti_frequency_trials", rate_hz=rate_hz, input=input)


def fetch_boucwen_benchmark(rate_hz: float | None | str = "default") -> DataSplit:
    """The Bouc-Wen benchmark (750 Hz; train multisine, test multisine and sine sweep)."""
    return load_preset("boucwen_benchmark", rate_hz=rate_hz)
