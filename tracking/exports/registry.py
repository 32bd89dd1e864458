"""Export formats by name: ``rehab track``'s options and ``write_results``' keywords come from here.

An export format is a subclass of :class:`ExportFormat` decorated with :func:`register`; the
built-in ones are the files of :mod:`tracking.exports.formats` (every module there is imported,
so a new format is a new file there). They are listed, and written, in the order of their
``rank``, then of their name.
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

from tracking.exports.tracked import TrackedRecording


class ExportFormat:
    """One file ``rehab track`` can write from a tracked recording (stateless).

    Class attributes:
        name: its keyword of :func:`tracking.drivers.offline.write_results` and
            ``track_recording`` (``trc=path``): lower-case letters, digits and '_'.
        options: its ``rehab track`` option(s), the first the one messages name (``("--out",)``).
        help: the option's help text.
        suffix: the file name's usual extension (``".trc"``).
        stem: the file name's stem in examples (``"markers"``: ``--out markers.trc``).
        rank: where it stands among the formats (options in ``rehab track --help``, files written).
    """

    name: ClassVar[str]
    options: ClassVar[tuple[str, ...]]
    help: ClassVar[str]
    suffix: ClassVar[str]
    stem: ClassVar[str]
    rank: ClassVar[int] = 100

    @property
    def option(self) -> str:
        """The option messages name (the first)."""
        return self.options[0]

    @property
    def dest(self) -> str:
        """The option's attribute on the parsed arguments (as argparse names it: ``--out`` -> ``out``)."""
        return self.option.lstrip("-").replace("-", "_")

    @property
    def example(self) -> str:
        """A file name for messages and docs (``markers.trc``)."""
        return self.stem + self.suffix

    def write(self, run: TrackedRecording, path: Path, *, asked: Path) -> None:
        """Write the file of ``run`` to ``path`` (a temporary file beside ``asked``, the file the
        user asked for, renamed to it once whole: a format never writes ``asked`` itself)."""
        raise NotImplementedError


_FORMATS: dict[str, ExportFormat] = {}


def register(cls: type[ExportFormat]) -> type[ExportFormat]:
    """Class decorator: make ``cls`` available under ``cls.name``.

    Raises:
        ValueError: a name or an option that is not well formed or is another format's.
    """
    name = cls.name
    if not name.isidentifier() or name != name.lower():
        raise ValueError(f"export format name {name!r}: use lower-case letters, digits and '_'")
    if not cls.options or not all(o.startswith("--") and len(o) > 2 for o in cls.options):
        raise ValueError(f"export format {name!r}: give its options as ('--name', ...)")
    if not cls.suffix.startswith(".") or not cls.stem or not cls.help:
        raise ValueError(f"export format {name!r}: give its suffix ('.ext'), a file stem and a help text")
    for other in _FORMATS.values():
        if other.name == name:
            if type(other).__qualname__ != cls.__qualname__:
                raise ValueError(f"export format {name!r} is registered twice ({type(other).__module__}, "
                                 f"{cls.__module__})")
            continue
        shared = set(other.options) & set(cls.options)
        if shared:
            raise ValueError(f"export format {name!r}: option {sorted(shared)[0]} is already {other.name!r}'s")
    _FORMATS[name] = cls()
    return cls


def unregister(name: str) -> None:
    """Forget the format called ``name`` (tests that register their own)."""
    _FORMATS.pop(name, None)


def formats() -> tuple[ExportFormat, ...]:
    """The registered formats in order (rank, then name)."""
    return tuple(sorted(_FORMATS.values(), key=lambda f: (f.rank, f.name)))


def names() -> tuple[str, ...]:
    """The registered formats' names in order."""
    return tuple(f.name for f in formats())


def get(name: str) -> ExportFormat:
    """The format called ``name`` (a ValueError lists the known ones)."""
    fmt = _FORMATS.get(name)
    if fmt is None:
        raise ValueError(f"export format {name!r} is not one of {', '.join(names())}")
    return fmt
