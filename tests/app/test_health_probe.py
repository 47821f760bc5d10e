"""/health answers when every connection of the service's pool is taken (issue 27
follow-up: under the load test jobs and requests hold the shared pool's connections; the
probe has a connection of its own and runs on the event loop, not in the shared thread
pool)."""

from __future__ import annotations

import threading
from typing import Any

from sqlalchemy.pool import QueuePool


def test_health_answers_while_every_pooled_connection_is_held(client: Any) -> None:
    engine = client.app.state.ctx.db.engine
    pool = engine.pool
    assert isinstance(pool, QueuePool)
    held = [engine.connect() for _ in range(pool.size() + pool._max_overflow)]
    box: dict[str, Any] = {}

    def probe() -> None:
        try:
            box["response"] = client.get("/health")
        except Exception as exc:  # surfaced below
            box["response"] = exc

    try:
        thread = threading.Thread(target=probe, daemon=True)
        thread.start()
        # bounded wait (hang detection, not a speed figure): before, the probe waited for
        # a pooled connection (pool timeout 30 s) and then failed with a 500
        thread.join(timeout=20)
        finished = not thread.is_alive()
    finally:
        for conn in held:
            conn.close()
    thread.join(timeout=60)
    assert finished, "/health waited for a connection of the shared pool"
    response = box["response"]
    assert not isinstance(response, Exception), response
    assert response.status_code == 200 and response.json()["status"] in ("ok", "warming")
