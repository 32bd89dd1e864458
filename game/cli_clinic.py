"""Clinic commands of ``rehab``: ROM tests, patients, the database, reports.

``rehab rom-test``, ``rehab rom-accuracy``, ``rehab rom-sdc``, ``rehab patients``, ``rehab export``, ``rehab import``,
``rehab backup``, ``rehab report``. Every command that touches the database takes ``--db PATH``
(default: the user's data directory, :func:`game.db.default_db_path`). Imports happen when a
command runs, so none of them loads pygame or OpenGL unless it renders the simulated patient.
"""

from __future__ import annotations

from pathlib import Path

from calibration.errors import RehabError
from game.cli_options import FPS, number


def add_commands(sub) -> None:
    """Register the clinic sub-commands on the ``rehab`` parser's sub-parsers."""
    _add_rom_test(sub)
    _add_rom_accuracy(sub)
    _add_rom_sdc(sub)
    _add_patients(sub)
    _add_export(sub)
    _add_import(sub)
    _add_backup(sub)
    _add_report(sub)


def _add_db(p) -> None:
    p.add_argument("--db", type=Path, default=None,
                   help="database file (default: the user's data directory, e.g. ~/.local/share/rehab/rehab.sqlite3)")


def _open_db(args, *, check_integrity: bool = True):
    """The command's database, checked in full at the command's start (``PRAGMA integrity_check``)."""
    from game.db import Database, default_db_path

    return Database(args.db or default_db_path(), check_integrity=check_integrity)


def _tell(message: str) -> None:
    """A progress line for the user (waiting for a locked database, a result kept aside)."""
    import sys

    print(f"rehab: {message}", file=sys.stderr, flush=True)


def _size(text: str) -> tuple[int, int]:
    from game.cli import _size as parse

    return parse(text)


# --------------------------------------------------------------------------- rom-test
def _add_rom_test(sub) -> None:
    p = sub.add_parser(
        "rom-test",
        help="run a ROM test headless (simulated patient) and store the result",
        description="Run a range-of-motion test with the same logic as the ROM test scene: check the start "
        "position, record while the patient moves, report the maximum (raw and rounded to 5 degrees) beside the "
        "normal value of the standard and the patient's previous results, flag compensation, and store an "
        "accepted result (active ROM, with the test position and the standard).",
    )
    p.add_argument("--patient", help="pseudonymous patient ID (see rehab patients)")
    p.add_argument("--test", help="ROM test name (content/rom_tests; --list shows them)")
    p.add_argument("--side", choices=("right", "left"), default="right", help="side tested (default: %(default)s)")
    p.add_argument("--standard", choices=("jarm", "aaos"), default="jarm",
                   help="reference standard the result is labelled with (default: %(default)s)")
    p.add_argument("--source", choices=("sim",), default="sim", help="where the samples come from (default: the simulated patient)")
    p.add_argument("--motion", default=None, help="simulated motion (default: the test's own motion for that side)")
    p.add_argument("--rig", default="ring4", help="camera layout of the simulator (default: %(default)s)")
    p.add_argument("--size", type=_size, default=(320, 240), help="camera image size WxH (default: 320x240)")
    p.add_argument("--fps", type=FPS, default=30.0, help="camera frame rate (default: %(default)s)")
    p.add_argument("--attempts", type=number(1, 100, integer=True), default=1,
                   help="attempts: a compensated attempt is discarded and repeated up to this many (default: %(default)s)")
    p.add_argument("--keep-compensated", action="store_true",
                   help="accept and store a compensated attempt (flagged) instead of discarding it")
    p.add_argument("--dry-run", action="store_true", help="print the result, store nothing")
    p.add_argument("--list", action="store_true", help="list the ROM tests and exit")
    _add_db(p)
    p.set_defaults(func=_cmd_rom_test)


def _cmd_rom_test(args) -> int:
    from game.rom.spec import available_rom_tests, check_side, load_all_rom_tests, load_rom_test

    if args.list:
        for t in load_all_rom_tests():
            refs = ", ".join(r.label() for r in t.references.values())
            print(f"{t.name:30s} {t.title}; reads {t.angle} x {t.direction:+d}; sides {'/'.join(t.sides)}; {refs}")
        return 0
    if not args.test:
        raise RehabError(f"give --test NAME: one of {', '.join(available_rom_tests())}")
    if not args.patient and not args.dry_run:
        raise RehabError("give --patient ID (or --dry-run to store nothing)")
    if args.attempts < 1:
        raise RehabError("--attempts must be 1 or more")
    test = load_rom_test(args.test)
    check_side(test, args.side)
    db = None
    previous = []
    if not args.dry_run:
        db = _open_db(args)
        db.require_patient(args.patient)
        previous = [r for r in db.rom_results(args.patient) if r.test == test.name and r.side == args.side]
    try:
        from game.rom.simulated import run_simulated_test

        def decide(result) -> bool:
            return args.keep_compensated or not result.compensated

        run = run_simulated_test(test, args.side, args.standard, motion=args.motion, rig=args.rig, size_px=args.size,
                                 fps=args.fps, max_attempts=args.attempts, decide=decide)
        for i, attempt in enumerate(run.attempts, 1):
            if not attempt.accepted:
                print(f"attempt {i}: {attempt.result.line()} -> discarded (compensation: repeat)")
        print(f"{run.frames} frame sets ({run.motion_s:.1f} s of motion {run.motion}) in {run.wall_s:.1f} s")
        accepted = run.accepted
        if accepted is None:
            why = "every attempt showed compensation" if run.attempts else f"the test did not finish ({run.last.message})"
            print(f"no result stored: {why}")
            return 2
        r = accepted.result
        ref = test.reference(args.standard)
        if ref is not None and not ref.comparable:
            print(f"reference: {ref.label()}")
        if previous:
            from game.rom.sdc import change_words

            hist = ", ".join(f"{p.session_started_utc[:10]} {round(p.value_deg / 5) * 5:g}" for p in previous[-5:])
            print(f"previous ({test.title}, {args.side}): {hist}")
            print(f"change from the previous session: {change_words(r.max_deg - previous[-1].value_deg, test.sdc_deg)}")
        number = next(i for i, a in enumerate(run.attempts, 1) if a.accepted)
        if db is None:
            print(f"attempt {number}: {r.line()} -> accepted (dry run: not stored)")
            return 0
        from game.db import pending, rom_record

        db.close()   # storing opens its own connection, waiting out another program's lock
        outcome = pending.store_durably(db.path, rom_record(args.patient, r, source=f"sim:{run.motion}"),
                                        wait_s=pending.WAIT_S, notify=_tell)
        # "accepted" only once the result is on disk (in the database, or in its pending file)
        print(f"attempt {number}: {r.line()} -> accepted")
        print(f"{outcome.line(db.path)} for patient {args.patient}")
        return 0
    finally:
        if db is not None:
            db.close()


# --------------------------------------------------------------------------- rom-accuracy
def _add_rom_accuracy(sub) -> None:
    p = sub.add_parser(
        "rom-accuracy",
        help="every ROM test on the simulated patient: recorded maximum against the truth, wall time",
        description="Run each ROM test (both sides where a simulated motion exists) on the simulated patient "
        "through the tracker and compare the recorded maximum with the maximum of the true markers; then the "
        "compensation motion (must be flagged) against its clean repetition (must not). Prints a Markdown table.",
    )
    p.add_argument("--test", action="append", default=None, help="test name (repeat; default: all)")
    p.add_argument("--rig", default="ring4")
    p.add_argument("--size", type=_size, default=(320, 240))
    p.add_argument("--fps", type=FPS, default=30.0)
    p.set_defaults(func=_cmd_rom_accuracy)


def _cmd_rom_accuracy(args) -> int:
    from game.rom.simulated import run_simulated_test
    from game.rom.spec import load_rom_test, load_all_rom_tests

    tests = [load_rom_test(n) for n in args.test] if args.test else load_all_rom_tests()
    print("| test | side | motion | recorded max | true max | error | start | compensation | estimated | frames | motion s | wall s |")
    print("| --- | --- | --- | ---: | ---: | ---: | ---: | --- | --- | ---: | ---: | ---: |")
    worst = 0.0
    for test in tests:
        for side in test.sides:
            if side not in test.simulated_motion:
                continue
            run = run_simulated_test(test, side, "jarm", rig=args.rig, size_px=args.size, fps=args.fps,
                                     decide=lambda r: True)
            if not run.attempts:
                print(f"| {test.name} | {side} | {run.motion} | not finished: {run.last.message} | | | | | | {run.frames} | "
                      f"{run.motion_s:.1f} | {run.wall_s:.1f} |", flush=True)
                continue
            a = run.attempts[0]
            r = a.result
            worst = max(worst, abs(a.error_deg))
            print(f"| {test.name} | {side} | {run.motion} | {r.max_deg:.1f} | {a.true_max_deg:.1f} | {a.error_deg:+.1f} | "
                  f"{r.start_deg:.1f} | {'; '.join(r.compensations) or 'none'} | {', '.join(r.estimated_markers) or '-'} | "
                  f"{run.frames} | {run.motion_s:.1f} | {run.wall_s:.1f} |", flush=True)
    comp = run_simulated_test(load_rom_test("shoulder_flexion"), "right", "jarm", motion="trunk_lean_compensation",
                              rig=args.rig, size_px=args.size, fps=args.fps, max_attempts=2, decide=lambda r: False)
    for i, a in enumerate(comp.attempts, 1):
        print(f"| shoulder_flexion (attempt {i}) | right | trunk_lean_compensation | {a.result.max_deg:.1f} | "
              f"{a.true_max_deg:.1f} | {a.error_deg:+.1f} | {a.result.start_deg:.1f} | "
              f"{'; '.join(a.result.compensations) or 'none'} | {', '.join(a.result.estimated_markers) or '-'} | "
              f"{comp.frames} | {comp.motion_s:.1f} | {comp.wall_s:.1f} |", flush=True)
    print(f"\nworst |error| over the tests: {worst:.1f} deg")
    return 0


# --------------------------------------------------------------------------- rom-sdc
def _add_rom_sdc(sub) -> None:
    from tracking.sim.population import REPORTED_SEEDS_FROM   # numpy only: no renderer

    p = sub.add_parser(
        "rom-sdc",
        help="measure each ROM test's smallest detectable change on the simulated patient",
        description="Repeat each ROM test on the simulated patient as new sessions of an unchanged patient (new "
        "sensor noise, the markers put on again with a placement error) through the renderer and the tracker; "
        "print each test's results, their spread, the standard error of measurement (SEM) and the smallest "
        "detectable change SDC95 = 1.96 * sqrt(2) * SEM, and the sdc: line for its content file. Seeds from "
        f"{REPORTED_SEEDS_FROM} on are the reported ones; smaller seeds are for tuning and tests.",
    )
    p.add_argument("--test", action="append", default=None, help="test name (repeat; default: all)")
    p.add_argument("--side", choices=("right", "left"), default="right", help="side measured (default: %(default)s)")
    p.add_argument("--draws", type=number(3, 1000, integer=True), default=10,
                   help="sessions per test (default: %(default)s)")
    p.add_argument("--first-seed", type=number(0, 2**31 - 1000, integer=True), default=REPORTED_SEEDS_FROM,
                   help="seed of the first session; the next ones count up (default: %(default)s)")
    p.add_argument("--rig", default="ring4")
    p.add_argument("--size", type=_size, default=(320, 240))
    p.add_argument("--fps", type=FPS, default=30.0)
    p.set_defaults(func=_cmd_rom_sdc)


def _cmd_rom_sdc(args) -> int:
    import datetime

    from game.rom.sdc import measure_sdc
    from game.rom.spec import load_all_rom_tests, load_rom_test

    tests = [load_rom_test(n) for n in args.test] if args.test else load_all_rom_tests()
    seeds = range(args.first_seed, args.first_seed + args.draws)
    print(f"seeds {seeds.start}-{seeds.stop - 1}, {args.side} side, rig {args.rig}, {args.size[0]}x{args.size[1]} "
          f"at {args.fps:g} fps")
    print("| test | n | failed | mean | SD = SEM | SEM 95 % CI | min | max | SDC95 | mean error vs truth | wall s |")
    print("| --- | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: |")
    lines = []
    today = datetime.date.today().isoformat()
    for test in tests:
        if args.side not in test.simulated_motion:
            print(f"| {test.name} | - | - | no simulated motion for the {args.side} side | | | | | | | |", flush=True)
            continue
        m = measure_sdc(test, args.side, seeds, size_px=args.size, fps=args.fps, rig=args.rig,
                        on_draw=lambda d: _tell(f"{d.seed}: {d.value_deg:.2f} deg (truth {d.true_deg:.2f}) "
                                                f"{d.message} in {d.wall_s:.1f} s"))
        e = m.estimate
        wall = sum(d.wall_s for d in m.draws)
        if e is None:
            print(f"| {test.name} | {len(m.draws) - m.failed} | {m.failed} | too few finished | | | | | | | {wall:.0f} |",
                  flush=True)
            continue
        err = [d.value_deg - d.true_deg for d in m.draws if d.message == ""]
        print(f"| {test.name} | {e.n} | {m.failed} | {e.mean_deg:.1f} | {e.sd_deg:.2f} | {e.sem_ci_deg[0]:.2f}-"
              f"{e.sem_ci_deg[1]:.2f} | {e.min_deg:.1f} | {e.max_deg:.1f} | {e.sdc95_deg:.1f} | "
              f"{sum(err) / len(err):+.2f} | {wall:.0f} |", flush=True)
        lines.append(f"{test.name}: sdc: {{sdc95_deg: {e.sdc95_deg:.1f}, sem_deg: {e.sem_deg:.2f}, n: {e.n}, "
                     f"side: {args.side}, seeds: {seeds.start}-{seeds.stop - 1}, measured: {today}}}")
    print()
    print("\n".join(lines))
    return 0


# --------------------------------------------------------------------------- patients
def _add_patients(sub) -> None:
    p = sub.add_parser("patients", help="list the patients (pseudonymous IDs), or add one",
                       description="List the patients with their sessions and results, or add one with --add.")
    p.add_argument("--add", metavar="ID", default=None, help="add a patient under this pseudonymous ID (no names)")
    p.add_argument("--note", default="",
                   help="a note for --add; it must not identify the patient (no names, birth dates or addresses)")
    _add_db(p)
    p.set_defaults(func=_cmd_patients)


def _cmd_patients(args) -> int:
    with _open_db(args) as db:
        if args.add:
            from game.db.database import identifying_hint

            db.add_patient(args.add, args.note)
            print(f"added patient {args.add} to {db.path}")
            hint = identifying_hint(args.note)
            if hint:
                _tell(f"warning: the note looks like it holds {hint}: notes must not identify the patient (no "
                      f"names, birth dates or addresses); the note is stored as given")
            return 0
        rows = db.patients()
        if not rows:
            print(f"no patients in {db.path}: add one with rehab patients --add P001")
            return 0
        print(f"{'patient':12s} {'added':20s} {'sessions':>8s} {'ROM':>5s} {'games':>6s}  last session")
        for r in rows:
            print(f"{r.id:12s} {r.created_utc:20s} {r.sessions:8d} {r.rom_results:5d} {r.exercise_results:6d}  {r.last_utc or '-'}")
    return 0


# --------------------------------------------------------------------------- export / import / backup
def _add_export(sub) -> None:
    p = sub.add_parser("export", help="export the database (or one patient) to CSV files")
    p.add_argument("--out", type=Path, required=True, help="folder for patients.csv, sessions.csv, rom_results.csv, exercise_results.csv, game_limits.csv")
    p.add_argument("--patient", default=None, help="only this patient (an empty ID is an error, not everyone)")
    p.add_argument("--fhir", action="store_true",
                   help="also write each patient's accepted ROM results as a FHIR R4 Bundle of Observations "
                        "(fhir/<patient>.json in the folder), validated before it is written")
    _add_db(p)
    p.set_defaults(func=_cmd_export)


def _cmd_export(args) -> int:
    with _open_db(args) as db:
        counts = db.export_csv(args.out, args.patient)
        print(f"exported {', '.join(f'{n} {k}' for k, n in counts.items())} to {args.out}")
        if args.fhir:
            from game.fhir_export import export_fhir

            fhir = export_fhir(db, args.out, args.patient)
            print(f"wrote {fhir['bundles']} FHIR bundles ({fhir['observations']} observations, validated) to "
                  f"{Path(args.out) / 'fhir'}")
    return 0


def _add_import(sub) -> None:
    p = sub.add_parser("import", help="import CSV files written by rehab export (rows already present are skipped)")
    p.add_argument("folder", type=Path, help="folder written by rehab export")
    _add_db(p)
    p.set_defaults(func=_cmd_import)


def _cmd_import(args) -> int:
    with _open_db(args) as db:
        counts = db.import_csv(args.folder)
    print(f"imported {', '.join(f'{n} {k}' for k, n in counts.items())} from {args.folder}")
    return 0


def _add_backup(sub) -> None:
    p = sub.add_parser("backup", help="copy the database to a backup file (consistent while in use)")
    p.add_argument("--out", type=Path, default=None,
                   help="backup file (default: rehab-backup-<UTC time>.sqlite3 beside the database)")
    _add_db(p)
    p.set_defaults(func=_cmd_backup)


def _cmd_backup(args) -> int:
    from game.db.database import utc_now

    with _open_db(args) as db:
        out = args.out or db.path.with_name(f"rehab-backup-{utc_now().replace(':', '')}.sqlite3")
        db.backup(out)
    print(f"backed up to {out}")
    return 0


# --------------------------------------------------------------------------- report
def _add_report(sub) -> None:
    p = sub.add_parser("report", help="HTML progress report of one patient (plots, table, CSV beside it)",
                       description="Write an HTML report of one patient for the clinic record: ROM per test over the "
                       "sessions with the normal band and the 5-degree grid, the table of results, repetitions and "
                       "session durations from the games; the table is also written as CSV beside the HTML.")
    p.add_argument("patient", help="pseudonymous patient ID")
    p.add_argument("--out", type=Path, required=True, help="HTML file to write (the CSV goes beside it)")
    p.add_argument("--standard", choices=("jarm", "aaos"), default="jarm", help="normal values shown (default: %(default)s)")
    _add_db(p)
    p.set_defaults(func=_cmd_report)


def _cmd_report(args) -> int:
    from game.report import write_report

    with _open_db(args) as db:
        html, csv_path = write_report(db, args.patient, args.out, standard=args.standard)
    print(f"wrote {html} and {csv_path}")
    return 0

