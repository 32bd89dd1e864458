"""Joint angles as an OpenSim motion file (``.mot``) that every OpenSim 4 reader reads whole.

The layout (OpenSim's ``Storage`` text format with the header OpenSim 4's own writer,
``STOFileAdapter``, gives a table of numbers)::

    angles                                          (the file's name)
    version=3
    nRows=<T>
    nColumns=<1 + A>
    inDegrees=yes
    DataType=double
    endheader
    time<TAB>left_shoulder_flexion<TAB>...<TAB>trunk_lateral_lean
    0.00000000<TAB>12.345678<TAB>...               (seconds, then degrees; NaN where undefined)

Why ``version=3``: OpenSim 4's ``Storage`` (behind the GUI's *File > Load Motion*, the tools'
motion inputs) reads a ``.mot`` of ``version`` 1 or less with its legacy number-by-number stream,
which stops at the first ``NaN`` (measured with opensim 4.6: a file cut after two rows); a higher
version goes through the file adapters (``TimeSeriesTable``), which read ``NaN`` as a missing
value, as OpenSim 4.6 itself writes it. Horizontal flexion and external rotation are undefined in
many frames by definition (docs/JOINT_ANGLES.md), so the undefined angles stay ``NaN`` and the
version says how to read them.

Columns are those of the angles CSV (``docs/JOINT_ANGLES.md``), times the recording's. These are
the project's clinical angles, not the coordinates of an OpenSim model: they plot and compare in
OpenSim but do not drive a model's coordinates by name.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

#: The header's ``version``: above 1, so that OpenSim's ``Storage`` reads ``NaN`` (module docstring);
#: 3 as OpenSim 4.6's ``STOFileAdapter`` writes.
STORAGE_VERSION = 3
_TIME_FORMAT = "%.8f"
_ANGLE_FORMAT = "%.6f"


def write_mot(path: str | Path, times_s: np.ndarray, angles_deg: Mapping[str, np.ndarray], *, name: str = "angles") -> None:
    """Write joint angles as an OpenSim ``.mot`` file (module docstring).

    Args:
        path: file to write.
        times_s: (T,) seconds, increasing.
        angles_deg: column name -> (T,) degrees, NaN where undefined (written ``NaN``, which
            OpenSim 4's readers take as missing), in column order.
        name: the first header line (OpenSim shows it as the motion's name).
    """
    t = np.asarray(times_s, dtype=np.float64)
    names = [str(k) for k in angles_deg]
    if t.ndim != 1 or not np.isfinite(t).all():
        raise ValueError("times_s must be (T,) finite seconds")
    if any(not n or any(c in n for c in " \t\r\n") for n in names) or "time" in names:
        raise ValueError(f"angle names {names} cannot be .mot column labels (no spaces, tabs, or 'time')")
    if any(c in name for c in "\r\n"):
        raise ValueError("name must be one line")
    values = (np.column_stack([np.broadcast_to(np.asarray(angles_deg[k], dtype=np.float64), t.shape) for k in names])
              if names else np.empty((len(t), 0)))
    header = [name or "angles", f"version={STORAGE_VERSION}", f"nRows={len(t)}", f"nColumns={1 + len(names)}",
              "inDegrees=yes", "DataType=double", "endheader", "\t".join(["time", *names])]
    row_format = "\t".join([_TIME_FORMAT] + [_ANGLE_FORMAT] * len(names))
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(header) + "\n")
        for time, row in zip(t.tolist(), values.tolist()):
            fh.write((row_format % (time, *row)).replace("nan", "NaN") + "\n")
