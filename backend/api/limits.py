"""A request body limit enforced while the body streams in (pure ASGI, before any parser)."""

from __future__ import annotations

import json

from starlette.types import ASGIApp, Message, Receive, Scope, Send

# Room for the multipart framing (boundaries, part headers, the form's other fields) on top
# of the files themselves, which `max_upload_bytes` is about.
FRAMING_BYTES = 64 * 1024


class BodyLimit:
    """Answer 413 when a request body passes `max_bytes` (+ FRAMING_BYTES).

    A Content-Length over the limit is refused before a byte of the body is read. A chunked
    (or lying) body is counted in `receive`: past the limit the 413 goes out at once, the
    application is told the client left, and whatever it still sends is dropped, so neither
    the multipart parser nor the route ever holds more than the limit.
    """

    def __init__(self, app: ASGIApp, max_bytes: int):
        self.app = app
        self.max_bytes = max_bytes
        self.limit = max_bytes + FRAMING_BYTES

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = _content_length(scope)
        if declared is not None and declared > self.limit:
            await self._reject(send)
            return
        state = {"received": 0, "rejected": False, "started": False}

        async def limited_receive() -> Message:
            if state["rejected"]:
                return {"type": "http.disconnect"}
            message = await receive()
            if message["type"] == "http.request":
                state["received"] += len(message.get("body", b""))
                if state["received"] > self.limit:
                    state["rejected"] = True
                    if not state["started"]:
                        await self._reject(send)
                    return {"type": "http.disconnect"}
            return message

        async def guarded_send(message: Message) -> None:
            if state["rejected"]:
                return  # the 413 is the answer; the app's late reply goes nowhere
            if message["type"] == "http.response.start":
                state["started"] = True
            await send(message)

        try:
            await self.app(scope, limited_receive, guarded_send)
        except Exception:
            # After a 413 the app fails on the cut-off body (a disconnect mid-form): that is
            # the expected end of the request, not a server error.
            if not state["rejected"]:
                raise

    async def _reject(self, send: Send) -> None:
        body = json.dumps(
            {"detail": f"request body larger than {self.max_bytes:,} bytes (upload limit)"}
        ).encode()
        await send(
            {
                "type": "http.response.start",
                "status": 413,
                "headers": [
                    (b"content-type", b"application/json"),
                    (b"content-length", str(len(body)).encode()),
                    (b"connection", b"close"),
                ],
            }
        )
        await send({"type": "http.response.body", "body": body})


def _content_length(scope: Scope) -> int | None:
    """The declared body length, or None (absent or unreadable: then counting decides)."""
    for name, value in scope.get("headers", ()):
        if name == b"content-length":
            try:
                return int(value)
            except ValueError:
                return None
    return None
