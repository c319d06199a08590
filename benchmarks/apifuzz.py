"""Every route under schemathesis: does the service answer what its OpenAPI promises?

Issue 25's figure: over every route with both scene kinds, 0 answers 5xx, 0 answers
outside the schema, 0 requests the schema calls valid that are rejected.  :func:`run_fuzz`
serves the given databases in one app (the app ``walkstream serve`` runs, called in
process through its ASGI interface), draws ``examples`` requests per operation and
generation mode (positive: valid per the schema; negative: invalid) with each scene
name fixed to a real scene (random names reach only the 404), and runs these checks on
every answer, counting failures instead of stopping at the first:

* ``not_a_server_error`` -- no 5xx;
* ``status_code_conformance``, ``content_type_conformance``,
  ``response_schema_conformance``, ``allow_header_conformance`` -- the answer is one
  the schema documents;
* ``positive_data_acceptance`` -- a valid request is not rejected (a 404 for a name
  that does not exist is an answer, not a rejection);
* ``negative_data_rejection`` -- an invalid one is not accepted.

``python -m walkstream.benchmarks.apifuzz CITY.db OFFICE.db [--examples 50]`` prints
one row per operation and mode, and the failures found (first example of each).
"""

from __future__ import annotations

import argparse
import os
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, cast

__all__ = ["CHECKS", "FuzzReport", "format_table", "run_fuzz"]

CHECKS = (
    "not_a_server_error",
    "status_code_conformance",
    "content_type_conformance",
    "response_schema_conformance",
    "allow_header_conformance",
    "positive_data_acceptance",
    "negative_data_rejection",
)
"""The schemathesis checks run on every answer."""


@dataclass
class FuzzRow:
    """One operation in one generation mode, for one scene."""

    scene: str
    operation: str
    mode: str
    examples: int = 0
    failures: Counter[str] = field(default_factory=Counter)


@dataclass
class FuzzReport:
    """What :func:`run_fuzz` found: rows, and the first message of each failure kind."""

    rows: list[FuzzRow] = field(default_factory=list)
    samples: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0

    def total(self) -> Counter[str]:
        """Failures by kind over every row."""
        out: Counter[str] = Counter()
        for r in self.rows:
            out.update(r.failures)
        return out


def _failures(exc: BaseException) -> list[BaseException]:
    """The single failures inside what ``call_and_validate`` raised."""
    if isinstance(exc, BaseExceptionGroup):
        return [f for e in exc.exceptions for f in _failures(e)]
    return [exc]


def _fuzz_test(strategy: Any, row: FuzzRow, report: FuzzReport, checks: list[Any], examples: int) -> Any:
    """A hypothesis test drawing ``examples`` cases from ``strategy`` into ``row``."""
    from hypothesis import HealthCheck, given, settings

    @given(case=strategy)
    @settings(
        max_examples=examples,
        deadline=None,
        database=None,
        derandomize=True,  # the same cases on every run
        suppress_health_check=list(HealthCheck),
    )
    def run(case: Any) -> None:
        row.examples += 1
        try:
            case.call_and_validate(checks=checks)
        except (Exception, BaseExceptionGroup) as exc:  # noqa: BLE001 - every failure is counted, none stops the run
            response = case.call()  # again, for the sample: the service answers the same
            for f in _failures(exc):
                kind = type(f).__name__
                row.failures[kind] += 1
                report.samples.setdefault(
                    kind,
                    f"{row.operation} {row.mode}: {case.as_curl_command()} -> "
                    f"{response.status_code} {response.text[:300]}",
                )

    return run


def run_fuzz(databases: Sequence[str | os.PathLike[str]], examples: int = 50) -> FuzzReport:
    """Run the schemathesis checks of :data:`CHECKS` over every operation, positive and
    negative, with every scene of ``databases`` in turn; see the module docs."""
    import schemathesis
    from hypothesis.errors import Unsatisfiable
    from schemathesis.checks import not_a_server_error
    from schemathesis.generation import GenerationMode
    from schemathesis.specs.openapi import checks as oas

    from walkstream.server.service.main import create_app
    from walkstream.server.store import SceneReader

    checks = [not_a_server_error, *(getattr(oas, name) for name in CHECKS[1:])]
    names = []
    for db in databases:
        with SceneReader.open(db) as r:
            names.append(r.meta.name)
    app = create_app(list(databases))
    report = FuzzReport()
    t0 = time.perf_counter()
    schema = schemathesis.openapi.from_asgi("/openapi.json", app)
    operations = [cast(Any, result).ok() for result in schema.get_all_operations()]
    for scene in names:
        for op in operations:
            for mode in GenerationMode:
                fixed = {"scene": scene} if "{scene}" in op.path else None
                strategy = op.as_strategy(generation_mode=mode, path_parameters=fixed)
                row = FuzzRow(scene, f"{op.method.upper()} {op.path}", mode.value)

                run = _fuzz_test(strategy, row, report, checks, examples)
                try:
                    run()
                except Unsatisfiable:
                    continue  # nothing invalid to generate (no parameters)
                report.rows.append(row)
    report.seconds = time.perf_counter() - t0
    return report


def format_table(report: FuzzReport) -> str:
    """The report as a plain-text table (one row per scene, operation and mode)."""
    lines = [f"{'scene':<10} {'mode':<9} {'operation':<48} {'cases':>6}  failures"]
    for r in report.rows:
        fails = ", ".join(f"{k} {v}" for k, v in sorted(r.failures.items())) or "-"
        lines.append(f"{r.scene[:10]:<10} {r.mode:<9} {r.operation[:48]:<48} {r.examples:>6}  {fails}")
    total = report.total()
    cases = sum(r.examples for r in report.rows)
    lines.append(
        f"{cases} cases in {report.seconds:.0f} s; failures: "
        + (", ".join(f"{k} {v}" for k, v in sorted(total.items())) or "none")
    )
    lines.extend(f"  {k}: {v}" for k, v in sorted(report.samples.items()))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry: fuzz the given databases and print the table; exit 1 on any failure."""
    ap = argparse.ArgumentParser(
        prog="python -m walkstream.benchmarks.apifuzz", description=(__doc__ or "").split("\n\n")[0]
    )
    ap.add_argument("databases", nargs="+", help="scene databases (a city and an interior)")
    ap.add_argument("--examples", type=int, default=50, help="requests per operation and mode")
    args = ap.parse_args(argv)
    report = run_fuzz(args.databases, args.examples)
    print(format_table(report))
    return 1 if report.total() else 0


if __name__ == "__main__":
    raise SystemExit(main())
