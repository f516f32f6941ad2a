"""The study's progress on the Dask dashboard's server: the page ``/prsm-progress``.

The study's process publishes its progress (points done, failed, total, time left: the text
bar's line, :class:`prsm_fmu.sweep.execute.Progress`) into the scheduler's metadata under
:data:`METADATA_KEY` (``Client.set_metadata``, at most every half second); this module's route,
which :func:`prsm_fmu.sweep.execute.local_cluster` adds to the scheduler's HTTP server (the
server of the dashboard, on the same loopback port), shows it on a page that reloads itself
every second.  It needs no bokeh (Dask's own dashboard pages do).  A scheduler started
elsewhere serves the page when its configuration lists this module among
``distributed.scheduler.http.routes`` (e.g. ``DASK_DISTRIBUTED__SCHEDULER__HTTP__ROUTES``).
"""

from __future__ import annotations

import html
from typing import Any, Callable

__all__ = ["METADATA_KEY", "PAGE", "ROUTE_MODULE", "page_served", "page_url", "publisher",
           "render", "routes"]

#: the scheduler metadata key the progress is published under
METADATA_KEY = "prsm-progress"
#: the page's path on the scheduler's HTTP server
PAGE = "prsm-progress"
#: this module, as ``distributed.scheduler.http.routes`` lists it
ROUTE_MODULE = __name__


def render(state: dict[str, Any] | None) -> str:
    """The page for a published progress ``state`` (None: no study has published yet)."""
    if not state:
        body = "<p>No study is running on this cluster yet.</p>"
    else:
        done, total, failed = int(state["done"]), int(state["total"]), int(state["failed"])
        left, skipped = state.get("left"), int(state.get("skipped") or 0)
        body = (f"<p><progress value='{done}' max='{max(total, 1)}'></progress></p>"
                f"<p>{done} of {total} points done, {failed} failed"
                f"{f', {skipped} done before' if skipped else ''}"
                f"; {float(state['elapsed']):.1f} s"
                f"{f', about {float(left):.0f} s left' if left is not None else ''}</p>"
                f"<pre>{html.escape(str(state.get('text', '')))}</pre>")
    return ("<!DOCTYPE html><html><head><meta charset='utf-8'>"
            "<meta http-equiv='refresh' content='1'><title>prsm-fmu study progress</title>"
            f"</head><body><h1>prsm-fmu study</h1>{body}</body></html>")


def page_url(dashboard_link: str) -> str:
    """The page's address from the cluster's dashboard link (``http://host:port/status``)."""
    base = dashboard_link.split("/status")[0].rstrip("/")
    return f"{base}/{PAGE}"


def page_served(client, timeout: float = 2.0) -> str | None:
    """The page's address if ``client``'s scheduler serves it (asked over HTTP, waiting at
    most ``timeout`` [s]), else None (a scheduler started without this module's route)."""
    import urllib.request

    link = getattr(client, "dashboard_link", None)
    if not link:
        return None
    url = page_url(link)
    try:
        with urllib.request.urlopen(url, timeout=timeout) as reply:
            return url if reply.status == 200 else None
    except Exception:  # noqa: BLE001 - unreachable or not served: no page to name
        return None


def publisher(client) -> Callable[[dict], None]:
    """A function that publishes a progress state to ``client``'s scheduler; a failure to
    reach it (the cluster closing) is ignored: the progress page is a view, not the study."""
    def publish(state: dict) -> None:
        try:
            client.set_metadata(METADATA_KEY, state)
        except Exception:  # noqa: BLE001 - see the docstring
            pass

    return publish


def _routes() -> list[tuple]:
    from distributed.http.utils import RequestHandler

    class ProgressPage(RequestHandler):
        def get(self) -> None:
            state = self.server.get_metadata([METADATA_KEY], default=None)
            self.set_header("Content-Type", "text/html; charset=utf-8")
            self.write(render(state))

    return [(PAGE, ProgressPage, {})]


#: the routes the scheduler's HTTP server loads from this module
routes: list[tuple] = _routes()
