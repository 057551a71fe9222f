"""ZenohBus(direct=True) (issue 16): node callbacks on Zenoh's network thread, with its Python
thread state kept (not made and freed per sample). Real Zenoh on loopback: a router and two client
sessions in this process."""
from __future__ import annotations

import threading

import pytest

from swarmhil.bus.zenoh_bus import ZenohBus, open_loopback_router


@pytest.mark.parametrize("direct", [True, False])
def test_samples_of_two_keys_arrive_in_publish_order_and_a_failing_callback_is_isolated(direct: bool) -> None:
    router, ep = open_loopback_router()
    rx, tx = ZenohBus(ep, direct=direct), ZenohBus(ep)
    try:
        got: list[tuple[str, bytes]] = []
        threads: set[int] = set()
        alive: list[bool] = []
        done = threading.Event()
        n = 400

        probed: set[str] = set()
        local = threading.local()  # kept across calls only if the thread's Python state is (zenoh_bus._pin_thread_state)
        fresh = [0]

        def on(key: str, payload: bytes) -> None:
            threads.add(threading.get_ident())
            if not getattr(local, "seen", False):
                local.seen = True
                fresh[0] += 1
            if payload == b"probe":
                probed.add(key.rsplit("/", 1)[-1])
                return
            got.append((key.rsplit("/", 1)[-1], payload))
            if payload == b"boom":
                raise RuntimeError("a node bug")  # logged; later samples still arrive
            if len(got) == 2 * n + 1:
                done.set()

        rx.subscribe("t/direct/a", on)
        rx.subscribe("t/direct/b", on)
        rx.watch_liveliness("t/direct/alive/*", lambda _k, up: alive.append(up))
        tok = tx.declare_liveliness("t/direct/alive/x")
        for _ in range(200):  # until both subscriptions reach the publisher's session
            tx.publish("t/direct/a", b"probe")
            tx.publish("t/direct/b", b"probe")
            if probed == {"a", "b"}:
                break
            threading.Event().wait(0.05)
        sent = []
        tx.publish("t/direct/a", b"boom")
        sent.append(("a", b"boom"))
        for i in range(n):
            for k in ("a", "b"):
                tx.publish(f"t/direct/{k}", str(i).encode())
                sent.append((k, str(i).encode()))
        assert done.wait(20), f"{len(got)} of {len(sent)} samples arrived"
        assert got == sent  # one session's samples on two keys: in the order they were published
        assert fresh[0] <= len(threads)  # a new Python thread state only once per thread, not per sample
        main = threading.get_ident()
        assert main not in threads
        if not direct:  # the dispatcher: one Python thread of its own
            assert threads == {rx._thread.ident}
        else:  # Zenoh's network thread(s), never the dispatcher
            assert rx._thread.ident not in threads
        tok.undeclare()
        for _ in range(100):
            if alive[-1:] == [False]:
                break
            threading.Event().wait(0.05)
        assert alive[0] is True and alive[-1] is False
    finally:
        rx.close()
        tx.close()
        router.close()
