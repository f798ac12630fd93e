"""What every HTML page of the project shares: the base style sheet and matplotlib figures as
embedded PNG bytes (the evaluation report, the policy campaign summary, the batch fleet page).
"""

from __future__ import annotations

import base64
import io

#: The pages' common look; each page appends the rules of its own elements.
BASE_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,Helvetica,Arial,sans-serif;margin:0;
 color:#1d2330;background:#f6f7f9;line-height:1.45}
header{background:#1d2330;color:#fff;padding:18px 28px}
header h1{margin:0;font-size:22px} header p{margin:4px 0 0;color:#c9d1e0;font-size:13px}
main{padding:8px 28px 40px;max-width:1500px}
section{background:#fff;border:1px solid #dde1e8;border-radius:6px;margin:18px 0;padding:14px 18px}
table{border-collapse:collapse;font-size:13px;margin:6px 0}
th,td{border:1px solid #dde1e8;padding:4px 8px;text-align:right;vertical-align:top}
th{background:#eef1f5} td.l,th.l{text-align:left}
.kpi{display:flex;flex-wrap:wrap;gap:10px;margin-bottom:8px}
.kpi div{background:#eef1f5;border-radius:5px;padding:8px 14px;font-size:13px}
.kpi b{display:block;font-size:20px}
figcaption{font-size:12px;color:#4a5468;margin-top:3px}
.small{font-size:12px;color:#4a5468}
"""


def figure_png(fig, dpi: int = 100, tight: bool = True) -> bytes:
    """A matplotlib ``Figure`` (made without pyplot) as PNG bytes."""
    # matplotlib's Agg canvas (0.5 s to import) only when a page is drawn
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight" if tight else None)
    return buf.getvalue()


def png_base64(data: bytes) -> str:
    """PNG bytes as base64 text, for a ``data:image/png;base64,`` URI."""
    return base64.b64encode(data).decode("ascii")
