"""The relay's byte-bounded FIFO on its own."""
import asyncio

import pytest

from pibr.server.byte_queue import ByteBudgetQueue


async def test_put_waits_until_the_bytes_fit_and_done_releases_them():
    q = ByteBudgetQueue(100)
    assert await q.put("a", 60) and await q.put("b", 40)
    third = asyncio.create_task(q.put("c", 30))
    await asyncio.sleep(0)
    assert not third.done() and q.held == 100
    assert await q.get() == ("a", 60)
    await asyncio.sleep(0)
    assert not third.done()                       # taken but not done: still counted
    await q.done(60)
    assert await asyncio.wait_for(third, 1) is True
    assert q.held == 70 and q.peak == 100
    assert [await q.get(), await q.get()] == [("b", 40), ("c", 30)]


async def test_an_abandoned_queue_refuses_further_items():
    q = ByteBudgetQueue(10)
    assert await q.put("a", 10)
    blocked = asyncio.create_task(q.put("b", 5))
    await asyncio.sleep(0)
    await q.abandon()
    assert await asyncio.wait_for(blocked, 1) is False and await q.put("c", 1) is False and q.held == 0


async def test_an_item_larger_than_the_budget_is_a_bug_not_a_wait():
    with pytest.raises(ValueError, match="never fits a budget of 10 bytes"):
        await ByteBudgetQueue(10).put("x", 11)
