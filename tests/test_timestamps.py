"""A mapped timestamp column's ``time_format`` reads its month, weekday and AM/PM names in
English whatever the process's locale (data/adapters/timestamps.py): pandas reads %b, %B, %a,
%A, %p and %c in LC_TIME, so a notebook or application that had called
``locale.setlocale(LC_ALL, "")`` under German refused every row of '25-Mar-2017 …' ("not a
date/time") and under Turkish the October rows; the CLI keeps LC_TIME=C."""

from __future__ import annotations

import locale
from datetime import datetime

import numpy as np
import pytest

from sumo_drvpw.data.adapters import read

#: (year, month, day, hour 0-23, minute, second), in order
WHEN = [(2017, 3, 25, 11, 46, 29), (2017, 3, 25, 11, 46, 30), (2017, 5, 2, 12, 0, 0),
        (2017, 10, 31, 13, 0, 0), (2017, 12, 1, 0, 0, 0), (2017, 12, 1, 0, 30, 0)]
MON = ["Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec"]
MONTH = ["January", "February", "March", "April", "May", "June", "July", "August", "September", "October",
         "November", "December"]
DAY = ["Monday", "Tuesday", "Wednesday", "Thursday", "Friday", "Saturday", "Sunday"]


def _cell(fmt: str, w) -> str:
    """``w`` written as ``fmt`` does in English, by hand (no strftime: it follows the locale too)."""
    y, mo, d, h, mi, s = w
    wd = datetime(y, mo, d).weekday()
    h12, ap = (h % 12 or 12), ("PM" if h >= 12 else "AM")
    return {"%d-%b-%Y %I:%M:%S %p": f"{d:02d}-{MON[mo - 1]}-{y} {h12:02d}:{mi:02d}:{s:02d} {ap}",
            "%A, %B %d %Y %I:%M:%S %p": f"{DAY[wd]}, {MONTH[mo - 1]} {d:02d} {y} {h12:02d}:{mi:02d}:{s:02d} {ap.lower()}",
            "%c": f"{DAY[wd][:3]} {MON[mo - 1]} {d:2d} {h:02d}:{mi:02d}:{s:02d} {y}"}[fmt]


@pytest.mark.parametrize("fmt", ["%d-%b-%Y %I:%M:%S %p", "%A, %B %d %Y %I:%M:%S %p", "%c"])
def test_a_time_format_s_names_are_read_in_english_in_any_locale(tmp_path, fmt):
    src = tmp_path / "t.csv"
    src.write_text("t,v\n" + "".join(f'"{_cell(fmt, w)}",{20 + i}\n' for i, w in enumerate(WHEN)), encoding="utf-8")
    m = tmp_path / "map.toml"
    m.write_text(f'[options]\ntime_unit = "datetime"\ntime_format = "{fmt}"\n[columns."t"]\nname = "time_s"\n'
                 '[columns."v"]\nname = "speed_mps"\nunit = "km/h"\n', encoding="utf-8")
    want = np.array([(datetime(*w) - datetime(*WHEN[0])).total_seconds() for w in WHEN])
    old = locale.setlocale(locale.LC_TIME)
    tried = 0
    try:
        for name in ("C", "de_DE.UTF-8", "tr_TR.UTF-8", "fr_FR.UTF-8"):
            try:
                locale.setlocale(locale.LC_TIME, name)
            except locale.Error:
                continue
            tried += 1
            df, _ = read("columns", src, m)
            np.testing.assert_array_equal(df["time_s"].to_numpy(float), want, err_msg=name)
    finally:
        locale.setlocale(locale.LC_TIME, old)
    if tried < 2:
        pytest.skip("no German, Turkish or French locale on this machine")


def test_timestamps_of_a_parquet_file_are_kept_whatever_the_time_format(tmp_path):
    """A Parquet column of timestamps has no text to read: the time_format's names are not
    read into it (1b749df's first form turned them into text and read every row as NaT)."""
    import pandas as pd

    src = tmp_path / "t.parquet"
    pd.DataFrame({"t": pd.to_datetime([datetime(*w) for w in WHEN]), "v": 20.0 + np.arange(len(WHEN))}).to_parquet(src)
    m = tmp_path / "map.toml"
    m.write_text('[options]\ntime_unit = "datetime"\ntime_format = "%d-%b-%Y %I:%M:%S %p"\n[columns."t"]\n'
                 'name = "time_s"\n[columns."v"]\nname = "speed_mps"\nunit = "km/h"\n', encoding="utf-8")
    want = np.array([(datetime(*w) - datetime(*WHEN[0])).total_seconds() for w in WHEN])
    np.testing.assert_array_equal(read("columns", src, m)[0]["time_s"].to_numpy(float), want)
