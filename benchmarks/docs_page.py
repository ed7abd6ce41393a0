"""Where the benchmarks' measured tables go, shared by every bench driver here.

Each bench writes its report (the measurement's header line, then its tables) to
docs/benchmarks/NAME.md: the one folder of measured results. With `--docs` it also points
docs/benchmarks.md at that report: the text between the bench's `<!-- MARKER:start -->` and
`<!-- MARKER:end -->` comments there becomes a link to the file and the report's header line
(when and where it was measured, by which command), so the page that explains each bench
names its latest run without copying its tables.
"""

import os
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "benchmarks"
PAGE = ROOT / "docs" / "benchmarks.md"


def write_result(name: str, text: str) -> pathlib.Path:
    """Writes `text` to docs/benchmarks/NAME (NAME with its extension) and returns the path."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / name
    path.write_text(text)
    return path


def point_page_at(marker: str, result: pathlib.Path, report: str) -> None:
    """Replaces the text between MARKER's comments in docs/benchmarks.md with a link to `result`
    and the first line of `report`; refuses a page without those markers."""
    text = PAGE.read_text()
    start, end = f"<!-- {marker}:start -->", f"<!-- {marker}:end -->"
    if start not in text or end not in text:
        raise SystemExit(f"{PAGE}: no {start} / {end} markers")
    link = pathlib.Path(os.path.relpath(result, PAGE.parent)).as_posix()
    first = report.strip().splitlines()[0] if report.strip() else ""
    first = first.replace("](docs/", "](")  # a link from the repository's root, seen from docs/
    new = f"{start}\nLatest run, in [{link}]({link}): {first}\n{end}"
    PAGE.write_text(re.sub(re.escape(start) + ".*?" + re.escape(end), lambda _: new, text, flags=re.S))
    print(f"updated {PAGE}")
