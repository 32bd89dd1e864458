"""Clinic commands of ``rehab``: ROM tests, patients, the database, reports.

``rehab rom-test``, ``rehab rom-accuracy``, ``rehab rom-sdc``, ``rehab patients``, ``rehab export``, ``rehab import``,
``rehab backup``, ``rehab report``, ``rehab db migrate|copy|check``. Every command that touches the
database takes ``--db PATH_OR_URL``: an SQLite file or a clinic's ``postgresql://`` server
(default: ``$REHAB_DB``, else the user's data directory, :func:`game.db.default_db_path`). Imports happen when a
command runs, so none of them loads pygame or OpenGL unless it renders the simulated patient.
"""

from __future__ import annotations

from pathlib import Path

from calibration.errors import RehabError
from game.cli_options import FPS, number, size_px


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
    _add_db_commands(sub)
    _add_accounts(sub)


DB_HELP = ("database: an SQLite file or a clinic's PostgreSQL server as postgresql://user@host:port/dbname "
           "(default: $REHAB_DB, else the user's data directory, e.g. ~/.local/share/rehab/rehab.sqlite3)")


USER_HELP = ("account to act as, where the database has accounts (default: $REHAB_USER); the password or PIN is "
             "asked, or read from $REHAB_PIN")


def _add_db(p) -> None:
    p.add_argument("--db", default=None, metavar="PATH_OR_URL", help=DB_HELP)
    p.add_argument("--user", default=None, metavar="NAME", help=USER_HELP)


def signed_in(user: str | None, db, action: str, patient_id: str | None = None):
    """The account allowed to do ``action`` (None where the database has no accounts: all may, as before).

    Raises:
        AccessDenied: no account given, a wrong secret, or an account that may not do it (one line).
    """
    import os
    import sys

    from game.db.accounts import AccessDenied, accounts_in_use, authenticate

    if not accounts_in_use(db):
        return None
    name = user or os.environ.get("REHAB_USER", "").strip()
    if not name:
        raise AccessDenied(f"{db.path} has accounts: give --user NAME (or set REHAB_USER)")
    secret = os.environ.get("REHAB_PIN")
    if secret is None:
        if not sys.stdin.isatty():
            raise AccessDenied(f"give the password or PIN of {name} (a terminal asks for it; or set REHAB_PIN)")
        import getpass

        secret = getpass.getpass(f"password or PIN of {name}: ")
    account = authenticate(db, name, secret)
    account.require(action, patient_id)
    return account


def _counts(counts: dict[str, int]) -> str:
    return ", ".join(f"{n} {k}" for k, n in counts.items())


def _audit(db, account, action: str, patient_id: str | None, what: str) -> None:
    from game.db.accounts import record

    record(db, account.name if account else "", action, patient_id, what)


def _open_db(args, *, check_integrity: bool = True):
    """The command's database, checked in full at the command's start (``PRAGMA integrity_check``)."""
    from game.db import Database

    return Database(args.db, check_integrity=check_integrity)


def _tell(message: str) -> None:
    """A progress line for the user (waiting for a locked database, a result kept aside)."""
    import sys

    print(f"rehab: {message}", file=sys.stderr, flush=True)


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
    p.add_argument("--size", type=size_px, default=(320, 240), help="camera image size WxH (default: 320x240)")
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
    offline_user = ""
    if not args.dry_run:
        import os

        from game.db import DatabaseUnreachable, db_location

        try:
            db = _open_db(args)
            account = signed_in(args.user, db, "accept", args.patient)
            db.require_patient(args.patient)
            previous = [r for r in db.rom_results(args.patient) if r.test == test.name and r.side == args.side]
        except DatabaseUnreachable as exc:   # the station goes on; the result waits on it (game.db.pending)
            _tell(f"{exc}; the test runs and its result is kept on this station until the server is back")
            db = None
            account = None
            offline_user = args.user or os.environ.get("REHAB_USER", "").strip()
        location = db_location(args.db)
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
        if args.dry_run:
            print(f"attempt {number}: {r.line()} -> accepted (dry run: not stored)")
            return 0
        from game.db import pending, rom_record

        if db is not None:
            db.close()   # storing opens its own connection, waiting out another program's lock
        record = rom_record(args.patient, r, source=f"sim:{run.motion}")
        if account is not None or offline_user:
            from dataclasses import replace

            # offline the name cannot be checked: the audit row says so
            record = replace(record, accepted_by=account.name if account else f"{offline_user} (not verified: offline)")
        outcome = pending.store_durably(location, record, wait_s=pending.WAIT_S, notify=_tell)
        # "accepted" only once the result is on disk (in the database, or in its pending file)
        print(f"attempt {number}: {r.line()} -> accepted")
        print(f"{outcome.line(location)} for patient {args.patient}")
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
    p.add_argument("--size", type=size_px, default=(320, 240))
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
    p.add_argument("--size", type=size_px, default=(320, 240))
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
        account = signed_in(args.user, db, "patients")
        if args.add:
            from game.db.database import identifying_hint

            db.add_patient(args.add, args.note)
            _audit(db, account, "change", args.add, "added the patient")
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
        account = signed_in(args.user, db, "export", args.patient)
        counts = db.export_csv(args.out, args.patient)
        _audit(db, account, "export", args.patient, f"CSV to {args.out}: {_counts(counts)}")
        print(f"exported {_counts(counts)} to {args.out}")
        if args.fhir:
            from game.fhir_export import export_fhir

            fhir = export_fhir(db, args.out, args.patient)
            _audit(db, account, "export", args.patient,
                   f"FHIR to {Path(args.out) / 'fhir'}: {fhir['bundles']} bundles, {fhir['observations']} observations")
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
        account = signed_in(args.user, db, "import")
        counts = db.import_csv(args.folder)
        _audit(db, account, "change", None, f"imported {args.folder}: {_counts(counts)}")
    print(f"imported {_counts(counts)} from {args.folder}")
    return 0


def _add_backup(sub) -> None:
    p = sub.add_parser("backup", help="copy the database to a backup file (consistent while in use)")
    p.add_argument("--out", type=Path, default=None,
                   help="backup file (default: rehab-backup-<UTC time>.sqlite3 beside the database)")
    _add_db(p)
    p.set_defaults(func=_cmd_backup)


def _cmd_backup(args) -> int:
    from game.db.database import utc_now
    from game.db.location import local_folder

    with _open_db(args) as db:
        account = signed_in(args.user, db, "backup")
        out = args.out or local_folder(db.path) / f"rehab-backup-{utc_now().replace(':', '')}.sqlite3"
        db.backup(out)
        _audit(db, account, "export", None, f"backup to {out}")
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
        account = signed_in(args.user, db, "report", args.patient)
        html, csv_path = write_report(db, args.patient, args.out, standard=args.standard)
        _audit(db, account, "export", args.patient, f"report {html}")
    print(f"wrote {html} and {csv_path}")
    return 0



# --------------------------------------------------------------------------- db migrate / copy / check
def _add_db_commands(sub) -> None:
    p = sub.add_parser("db", help="the database itself: migrate the schema, copy a clinic to another database, "
                       "check it",
                       description="migrate: bring the database (a file or a postgresql:// server) to this rehab's "
                       "schema; copy: move every patient, session, result and limit to another database (e.g. an "
                       "SQLite file to the clinic's PostgreSQL server) and compare both; check: the integrity checks.")
    dsub = p.add_subparsers(dest="db_command", required=True, metavar="migrate|copy|check")
    m = dsub.add_parser("migrate", help="create or upgrade the schema (every command also does it when it opens)")
    _add_db(m)
    m.set_defaults(func=_cmd_db_migrate)
    c = dsub.add_parser("copy", help="copy all history from one database to another, then compare them",
                        description="Copy every row from SOURCE to DEST in one transaction (rows DEST already has are "
                        "kept; running it again adds nothing), then compare both row by row.")
    c.add_argument("source", help="database to copy from (SQLite file or postgresql:// URL)")
    c.add_argument("dest", help="database to copy into (postgresql:// URL, or a new SQLite file)")
    c.add_argument("--user", default=None, metavar="NAME", help=USER_HELP)
    c.set_defaults(func=_cmd_db_copy)
    k = dsub.add_parser("check", help="integrity checks: orphans, missing or duplicate uids, SQLite's page check")
    _add_db(k)
    k.set_defaults(func=_cmd_db_check)


def _cmd_db_migrate(args) -> int:
    from game.db import LATEST_VERSION, Database

    with Database(args.db, check_integrity=True) as db:
        print(f"{db.path}: schema version {db.schema_version} (this rehab writes {LATEST_VERSION}, {db.dialect.name})")
    return 0


def _cmd_db_copy(args) -> int:
    from game.db import Database, db_location
    from game.db.copy import copy_database, differences

    source, dest = db_location(args.source), db_location(args.dest)
    if source == dest:
        raise RehabError(f"{source} is both the source and the destination: give two databases")
    if isinstance(source, Path) and not source.is_file():
        raise RehabError(f"{source}: no such database file: give the SQLite file to copy")
    with Database(source, check_integrity=True, store_pending=False) as src, Database(dest, store_pending=False) as dst:
        account = signed_in(args.user, src, "export")
        _audit(src, account, "export", None, f"copied to {dest}")   # first: the copy carries it too
        counts = copy_database(src, dst)
        for table, (added, present) in counts.items():
            print(f"{table:17s} {added:6d} copied" + (f", {present} already in {dst.path}" if present else ""))
        diff = differences(src, dst)
    if diff:
        for table, (missing, extra) in diff.items():
            print(f"{table}: {missing} rows of {source} differ or are missing in {dest}, {extra} rows only in {dest}")
        print(f"the databases differ: {dest} held other data before the copy (see above)")
        return 1
    print(f"{dest} now holds exactly the rows of {source} (compared row by row)")
    return 0


def _cmd_db_check(args) -> int:
    from game.db.copy import integrity_problems

    with _open_db(args) as db:
        problems = integrity_problems(db)
        for p in problems:
            print(f"{db.path}: {p}")
        if not problems:
            print(f"{db.path}: all integrity checks pass ({db.dialect.name}, schema version {db.schema_version})")
    return 1 if problems else 0


# --------------------------------------------------------------------------- accounts / audit
def _add_accounts(sub) -> None:
    p = sub.add_parser("accounts", help="therapist and patient accounts (who may do what), or add one",
                       description="List the accounts, or add one with --add. The first therapist account may be "
                       "added by anyone; from then on only a therapist adds accounts, and the commands that run ROM "
                       "tests, accept results, change patients, write reports or export need a therapist (--user). A "
                       "patient account may only play its own patient's games. The password or PIN is asked (or "
                       "read from $REHAB_NEW_PIN) and stored only as a scrypt hash.")
    p.add_argument("--add", metavar="NAME", default=None, help="add an account under this name (never a real name)")
    p.add_argument("--role", choices=("therapist", "patient"), default="therapist", help="(default: %(default)s)")
    p.add_argument("--patient", default=None, help="the patient of a patient account")
    p.add_argument("--audit", action="store_true", help="list the audit record instead (who did what, when)")
    _add_db(p)
    p.set_defaults(func=_cmd_accounts)


def _cmd_accounts(args) -> int:
    import os
    import sys

    from game.db.accounts import accounts, accounts_in_use, add_account, audit_rows

    with _open_db(args) as db:
        first = not accounts_in_use(db)
        if not (first and args.add and args.role == "therapist"):
            account = signed_in(args.user, db, "accounts")
        else:
            account = None   # the first therapist account: whoever runs rehab on this database
        if args.audit:
            for r in audit_rows(db, args.patient):
                print(f"{r.at_utc}  {r.account:12s} {r.action:8s} {r.patient_id or '-':10s} {r.what}")
            return 0
        if args.add:
            secret = os.environ.get("REHAB_NEW_PIN")
            if secret is None:
                if not sys.stdin.isatty():
                    raise RehabError(f"give the new password or PIN of {args.add} (a terminal asks; or set "
                                     f"REHAB_NEW_PIN)")
                import getpass

                secret = getpass.getpass(f"new password or PIN of {args.add}: ")
                if getpass.getpass("again: ") != secret:
                    raise RehabError("the two entries differ: nothing added")
            new = add_account(db, args.add, args.role, secret, args.patient)
            _audit(db, account or new, "change", new.patient_id, f"added {new.role} account {new.name}")
            print(f"added {new.role} account {new.name}" + (f" for patient {new.patient_id}" if new.patient_id else ""))
            return 0
        rows = accounts(db)
        if not rows:
            print(f"no accounts in {db.path}: everyone who can open it may do everything (add a therapist with "
                  f"rehab accounts --add NAME)")
        for a in rows:
            print(f"{a.name:16s} {a.role:10s} {a.patient_id or ''}")
    return 0
