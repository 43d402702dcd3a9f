"""The notebook client of the kit's own notebook runs: ``snakekit check``, the grader's sandboxes
and the suite's notebook runs.

nbclient waits for each cell's ``execute_reply`` on the shell channel. Now and then the kernel
(ipykernel 7) runs a cell to its end, says on IOPub that it is idle with every output sent, and
that reply never arrives: nbclient would then wait out the cell's whole timeout, and a cell that
did its work would count as one that ran too long. Under a busy machine this happens most to
cells whose widgets send messages of their own (lesson 0's control panel).

:class:`LateReplies`, mixed in front of ``nbclient.NotebookClient`` or a subclass of it (nbgrader's
``Execute``), gives the reply :data:`LATE_REPLY` s once the kernel has said it is idle; then the
cell counts as finished with the outputs it sent (an error output as its last output stays the
cell's error) and the run goes on. :meth:`LateReplies.reply_never_came` is told of each such cell.

This module imports nothing of the kit: the grader's sandbox (``grader.sandbox.inside``) uses it too.
"""

from __future__ import annotations

import asyncio
import typing as t

import nbclient

#: How long after a cell's kernel said it is idle (IOPub) its reply (shell) may still be on its way [s].
#: A reply follows the idle within milliseconds; this is a bound for a busy machine (a reply that comes
#: after it is one a later cell ignores, as nbclient ignores replies to other requests).
LATE_REPLY = 5.0


class LateReplies:
    """Mix in before ``nbclient.NotebookClient`` (or its subclass): a lost ``execute_reply`` costs
    :data:`LATE_REPLY` s after the cell's idle, not the cell's timeout."""

    def reply_never_came(self, cell: t.Any) -> None:
        """Called for a cell taken as finished without its reply (override to count or report)."""
        self.log.warning("cell %s: the kernel finished it but its reply never came; taken as finished after %g s",
                         cell.get("id"), LATE_REPLY)

    async def _async_poll_for_reply(self, msg_id, cell, timeout, task_poll_output_msg, task_poll_kernel_alive):
        reply = asyncio.ensure_future(super()._async_poll_for_reply(  # type: ignore[misc]
            msg_id, cell, timeout, task_poll_output_msg, task_poll_kernel_alive))
        await asyncio.wait({reply, task_poll_output_msg}, return_when=asyncio.FIRST_COMPLETED)
        if reply.done() or task_poll_output_msg.cancelled() or task_poll_output_msg.exception() is not None:
            return await reply
        try:  # the kernel said it is idle: its reply is due now
            return await asyncio.wait_for(asyncio.shield(reply), LATE_REPLY)
        except asyncio.TimeoutError:
            reply.cancel()
            task_poll_kernel_alive.cancel()
        self.reply_never_came(cell)
        return {"parent_header": {"msg_id": msg_id}, "header": {"msg_type": "execute_reply"}, "metadata": {},
                "content": {**reply_from_outputs(cell.get("outputs", [])), "execution_count": cell.get("execution_count")}}


def reply_from_outputs(outputs: list) -> dict:
    """The content of the reply a cell with these outputs had: its error when its last output is one."""
    last = outputs[-1] if outputs else {}
    if last.get("output_type") != "error":
        return {"status": "ok"}
    return {"status": "error", "ename": last.get("ename", ""), "evalue": last.get("evalue", ""),
            "traceback": last.get("traceback", [])}


class NotebookClient(LateReplies, nbclient.NotebookClient):
    """``nbclient.NotebookClient`` that a lost reply does not hold up (:class:`LateReplies`)."""
