"""One self-contained HTML report (plots embedded as PNG) of a diagnosis or of the whole
loop, and the same numbers as JSON.

::

    h = popup.improve(model, run)
    popup.report.write_html(h, "report.html")
    popup.report.write_json(h, "report.json")
"""

from __future__ import annotations

import base64
import html
import io
import json
import os
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Union

from .diagnosis import Diagnosis, History

__all__ = ["write_html", "write_json", "to_html", "write_section"]

PathLike = Union[str, "os.PathLike[str]"]


def _png(fig: Any) -> str:
    import matplotlib.pyplot as plt

    fig = getattr(fig, "figure", fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _img(fig: Any, alt: str) -> str:
    return f'<figure><img alt="{html.escape(alt)}" src="{_png(fig)}"/><figcaption>{html.escape(alt)}</figcaption></figure>'


def _as_history(result: Union[History, Diagnosis]) -> History:
    if isinstance(result, History):
        return result
    if isinstance(result, Diagnosis):
        from .diagnosis import HistoryStep

        return History([HistoryStep([], {}, result.nominal_error, result.channel_error)], [result], result.conclusion, run=result.run, seconds=result.seconds)
    raise TypeError(f"report: expected a popup History or Diagnosis, got {type(result).__name__}")


def to_html(result: Union[History, Diagnosis], *, title: str = "popup diagnosis") -> str:
    """The report as one HTML string (no external files or scripts)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    h = _as_history(result)
    parts: List[str] = []
    parts.append(f"<h1>{html.escape(title)}</h1>")
    parts.append(f"<p><b>Run:</b> {html.escape(h.run)}<br/><b>Conclusion:</b> {html.escape(h.conclusion)}</p>")
    if h.error:
        parts.append(f"<p style='color:#a00'><b>Incomplete:</b> {html.escape(h.error)} (what finished before is below)</p>")
    from .diagnosis import ERROR_DEFINITION

    fall = " → ".join(f"{s.error:.4g}" for s in h.steps)
    parts.append(f"<p><b>Systematic error</b> in noise units ({html.escape(ERROR_DEFINITION)}): {fall}</p>")
    enc, floor = h.encoder_floor, h.at_floor
    rows = "".join(
        f"<tr><td>{html.escape(c)}</td><td>{h.noise.get(c, float('nan')):.4g}</td><td>{v:.3g}×</td><td>{h.steps[-1].channel_error.get(c, float('nan')):.3g}×</td>"
        f"<td>{enc.get(c, 1.0):.3g}×</td>"
        f"<td>{'yes' if c in floor else ''}</td></tr>"
        for c, v in h.steps[0].channel_error.items()
    )
    parts.append("<table><tr><th>channel</th><th>noise σ</th><th>nominal (× noise)</th><th>final (× noise)</th>"
                 "<th>encoder floor (× noise)</th><th>signal at noise floor</th></tr>" + rows + "</table>")
    if not h.diagnoses:
        return _page(title, parts + _loop_notes(h), h)
    d0 = h.diagnoses[0]
    cmp = d0.comparison
    parts.append("<h2>1. Comparison of the nominal model with the run</h2>")
    parts.append(cmp.to_pandas().to_html(float_format=lambda x: f"{x:.4g}"))
    parts.append(_img(cmp.plot("overlay"), "measured vs model, nominal"))
    parts.append(_img(cmp.plot("residuals"), "residual views: time series, whiteness, cross-correlation, spectrum"))
    parts.append("<h3>Where the model fails</h3>")
    parts.append(cmp.windows.head(5).to_html(float_format=lambda x: f"{x:.3g}"))
    parts.append(cmp.conditions.to_html(float_format=lambda x: f"{x:.3g}"))
    parts.append("<h2>2. Suspects (every effect of the library, ranked)</h2>")
    parts.append(d0.to_pandas().to_html(float_format=lambda x: f"{x:.4g}"))
    parts.append(_img(d0.plot(), "error with each effect fitted"))
    if len(h.diagnoses) > 1:
        for i, d in enumerate(h.diagnoses[1:], 2):
            st = next((x for x in h.steps if d.problem is not None and x.model is d.problem.model), None)
            has = st.effects if st is not None else h.steps[min(i - 1, len(h.steps) - 1)].effects
            parts.append(f"<h3>Round {i}: the model with {html.escape(', '.join(has) or 'nothing added')}</h3>")
            parts.append(f"<p>{html.escape(d.conclusion)}</p>")
            parts.append(d.to_pandas().head(5).to_html(float_format=lambda x: f"{x:.4g}"))
    parts.append("<h2>3. Error history</h2>")
    parts.append(h.to_pandas().to_html(float_format=lambda x: f"{x:.4g}"))
    parts.extend(_loop_notes(h))
    parts.append(_img(h.plot(), "the fall of the error"))
    if len(h.diagnoses) > 1 or len(h.steps) > 1:
        last = h.diagnoses[-1].comparison
        parts.append(_img(last.plot("overlay"), "measured vs final model"))
    parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in cmp.notes) + "</ul>")
    return _page(title, parts, h)


def _loop_notes(h: History) -> List[str]:
    """The loop's notes: what its swap and base-law steps tried and why each was (not)
    kept, and where a refitted model's residual gave some channel's noise floor anew."""
    if not h.notes:
        return []
    return ["<p><b>Notes of the loop</b> (swaps and base laws tried, noise floors re-estimated):</p><ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in h.notes) + "</ul>"]


def _page(title: str, parts: List[str], h: History) -> str:
    data = json.dumps(h.to_dict(), allow_nan=False).replace("</", "<\\/")
    css = "body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:collapse;font-size:12px}td,th{border:1px solid #ccc;padding:2px 6px}img{max-width:100%}"
    return (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'/><title>{html.escape(title)}</title><style>{css}</style></head><body>"
        + "\n".join(parts)
        + f"<script type='application/json' id='popup-data'>{data}</script></body></html>"
    )


def write_html(result: Union[History, Diagnosis], path: PathLike, *, title: str = "popup diagnosis") -> Path:
    """Write the self-contained HTML report; returns its path."""
    p = Path(os.fspath(path))
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(to_html(result, title=title), encoding="utf-8")
    return p


def write_json(result: Union[History, Diagnosis], path: PathLike) -> Path:
    """Write the numbers of the report as JSON (the CLI's ``--json`` object)."""
    p = Path(os.fspath(path))
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(_as_history(result).to_dict(), indent=1, allow_nan=False), encoding="utf-8")
    return p


def write_section(path: PathLike, key: str, body: str, *, title: Optional[str] = None, order: Sequence[str] = ()) -> Path:
    """Replace (or add) the generated section ``key`` of a markdown results page shared by
    several scripts, keeping the others and the page's heading. Sections sit between
    ``<!-- begin: key -->`` and ``<!-- end: key -->`` markers, those named in ``order``
    first, then in the order found (a new one last). ``title`` heads a new page (or
    replaces the heading of an existing one)."""
    import re

    path = Path(path)
    sections: Dict[str, str] = {}
    head = title
    if path.exists():
        text = path.read_text(encoding="utf-8")
        if head is None:
            head = text.split("<!-- begin: ", 1)[0]
        for m in re.finditer(r"<!-- begin: (\w+) -->\n(.*?)<!-- end: \1 -->\n", text, re.S):
            sections[m.group(1)] = m.group(2)
    if head is None:
        head = f"# {path.stem}\n\nEach section below is written by a script (between its markers); rerun it to refresh.\n"
    sections[key] = body.rstrip("\n") + "\n"
    keys = [k for k in order if k in sections] + [k for k in sections if k not in order]
    out = head.rstrip("\n") + "\n" + "".join(f"\n<!-- begin: {k} -->\n{sections[k]}<!-- end: {k} -->\n" for k in keys)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(out, encoding="utf-8")
    return path
