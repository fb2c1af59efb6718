"""metrics.csv: every scalar of every generation, one row per generation (`CsvReporter`), and
reading it back checked (`read_metrics_csv`)."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from ..coevo.evolve import Evolution, GenerationResult
from .files import METRICS_FILE
from .records import SCALAR_TAGS, scalars
from .reporter import Reporter


class CsvReporter(Reporter):
    """Appends every generation's scalars (`records.scalars`) to metrics.csv in the run directory:
    one row per generation, the header (`generation` and the tags) once; each row is written
    (unbuffered) when its generation ends. On a resume, rows of generations the run repeats (those after its checkpoint)
    are dropped first, so the file keeps one row per generation; a header that lacks some of
    the tags gets them (earlier rows leave them empty)."""

    def __init__(self, run_dir: Path):
        self.path = Path(run_dir) / METRICS_FILE
        self.columns: list[str] | None = None

    def on_start(self, ev: Evolution) -> None:
        if not self.path.is_file():
            return
        rows, columns = read_metrics_csv(self.path, raw=True)
        rows = [r for r in rows if r["generation"] < ev.state.generation]
        self._rewrite(columns, rows)

    def _rewrite(self, columns: list[str], rows: list[dict]) -> None:
        from .files import atomic_write_bytes

        buf = io.StringIO()
        w = csv.DictWriter(
            buf, fieldnames=columns, restval="", extrasaction="ignore", lineterminator="\n"
        )
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if v is None else v) for k, v in r.items()})
        atomic_write_bytes(self.path, buf.getvalue().encode())
        self.columns = list(columns)

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        row = {k: (int(v) if isinstance(v, bool) else v) for k, v in scalars(result).items()}
        if self.columns is None or not set(row) <= set(self.columns):
            old, _ = read_metrics_csv(self.path, raw=True) if self.path.is_file() else ([], [])
            self._rewrite(
                (self.columns or []) + [k for k in row if k not in (self.columns or [])], old
            )
        from .files import append_line

        buf = io.StringIO()
        csv.DictWriter(buf, fieldnames=self.columns, restval="", lineterminator="").writerow(
            {k: ("" if v is None else v) for k, v in row.items()}
        )
        append_line(self.path, buf.getvalue())  # one os.write: on disk when it returns

    def on_end(self, ev: Evolution) -> None:
        pass


def _number(text: str):
    if text == "":
        return None
    try:
        return int(text)
    except ValueError:
        return float(text)


def read_metrics_csv(path: Path, raw: bool = False) -> tuple[list[dict], list[str]]:
    """The rows of a metrics.csv (numbers as int or float, empty cells None; a last row cut
    short by an interruption is skipped; any other row with more or fewer cells than the header,
    or whose generation or a cell is not a number, is a RunError naming it) and its header. With
    `raw`, the cells other than `generation` are kept as text. The file is read without
    following a link and up to `files.MAX_RECORD_BYTES`; RunError naming the file for one that
    cannot be read, is not UTF-8 or not CSV, or whose header is not metrics.csv's (no
    `generation` column, or columns that are no tag: a resume would otherwise drop its rows)."""
    from .files import MAX_RECORD_BYTES, RunError, read_text

    text = read_text(path, MAX_RECORD_BYTES)
    try:
        reader = csv.DictReader(io.StringIO(text, newline=""))
        columns = list(reader.fieldnames or [])
        unknown = [c for c in columns if c != "generation" and c not in SCALAR_TAGS]
        if columns and ("generation" not in columns or unknown or len(set(columns)) < len(columns)):
            what = (
                f"unknown columns {', '.join(repr(c[:40]) for c in unknown[:5])}"
                if unknown
                else "no 'generation' column"
                if "generation" not in columns
                else "a column named twice"
            )
            raise RunError(
                f"{path}: not a metrics.csv header ({what}); restore the header or "
                "move the file away"
            )
        rows = []
        records = list(reader)
        for i, r in enumerate(records):
            if any(v is None for v in r.values()) and None not in r and i == len(records) - 1:
                continue  # fewer cells than the header in the last line: cut short by a kill
            problem = None
            if None in r:
                problem = "more cells than the header"
            elif any(v is None for v in r.values()):
                problem = "fewer cells than the header"
            else:
                try:
                    gen = int(r["generation"])
                    row = {k: (v if raw else _number(v)) for k, v in r.items()}
                except (KeyError, ValueError):
                    problem = (
                        f"generation {str(r.get('generation'))[:20]!r} or a cell is not a number"
                    )
            if problem is not None:
                # a damaged row inside the file: refused, so that a resume does not drop it
                raise RunError(
                    f"{path}: data row {i + 1} is damaged ({problem}); repair or remove that row, "
                    "or move the file away"
                )
            row["generation"] = gen
            rows.append(row)
    except csv.Error as e:
        raise RunError(f"{path}: malformed CSV ({e})") from None
    return rows, columns
