"""Fits that meet at one forward model: their FE runs solved together, in one thread.

Several fits (one per specimen, site or rate) run the fit engine's Levenberg-Marquardt, each
in its own thread, with its own damping, accepted and rejected steps and stopping test,
exactly as it would alone. What they share is the forward model: a fit's thread hands its
request for FE runs to :meth:`FitMeeting.request` and waits; whenever every fit still
running has a request waiting, :meth:`FitMeeting.serve`, in the thread that started the
fits, solves them all together and hands each its answer. A fit that has stopped leaves
(:meth:`FitMeeting.leave`); the others go on. The FE runs in one thread because the GPU's
libraries keep per-thread state (nvmath's cuDSS handles fail in a thread other than the one
that first used them).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

__all__ = ["FitMeeting", "run_fits"]


class FitMeeting:
    """Collects the fits' requests; the serving thread answers them all at once.

    Args:
        count: The number of fits (numbered 0 .. count - 1).
        solve: Answers a batch of requests, ``{fit: request} -> {fit: answer}``; an
            answer may be an exception, raised in that fit's thread.
    """

    def __init__(self, count: int, solve: Callable[[dict[int, Any]], dict[int, Any]]) -> None:
        self._condition = threading.Condition()
        self._solve = solve
        self._live = set(range(count))
        self._pending: dict[int, Any] = {}
        self._answers: dict[int, Any] = {}
        self._stopped: BaseException | None = None

    def request(self, fit: int, request: Any) -> Any:
        """Hand in fit ``fit``'s request and wait for its answer (raised where it is an
        exception)."""
        with self._condition:
            if self._stopped is not None:
                raise self._stopped
            self._pending[fit] = request
            self._condition.notify_all()
            self._condition.wait_for(lambda: fit in self._answers)
            answer = self._answers.pop(fit)
        if isinstance(answer, BaseException):
            raise answer
        return answer

    def leave(self, fit: int) -> None:
        """Fit ``fit`` has stopped: the others no longer wait for it."""
        with self._condition:
            self._live.discard(fit)
            self._condition.notify_all()

    def serve(self) -> None:
        """Answer batches in this thread until every fit has left.

        An exception of a batch is handed to each fit of that batch. An interrupt (Ctrl-C)
        is handed to every waiting fit and to every later request, so that the fit threads
        end, and raised here.
        """
        batch: dict[int, Any] = {}
        try:
            while True:
                with self._condition:
                    self._condition.wait_for(
                        lambda: (
                            not self._live
                            or (bool(self._pending) and set(self._pending) >= self._live)
                        )
                    )
                    if not self._live:
                        return
                    batch, self._pending = self._pending, {}
                try:
                    answers = self._solve(batch)
                except Exception as exc:  # every fit of the batch gets the error
                    answers = dict.fromkeys(batch, exc)
                with self._condition:
                    self._answers.update(answers)
                    batch = {}
                    self._condition.notify_all()
        except BaseException as exc:  # Ctrl-C: every fit stops
            with self._condition:
                self._stopped = exc
                for fit in {**batch, **self._pending}:
                    self._answers[fit] = exc
                self._pending = {}
                self._condition.notify_all()
            raise


def run_fits(
    count: int,
    solve: Callable[[dict[int, Any]], dict[int, Any]],
    fit: Callable[[int, FitMeeting], Any],
) -> list[Any]:
    """Run ``fit(k, meeting)`` for k = 0 .. count - 1, each in its own thread, meeting at one
    :class:`FitMeeting` whose batches ``solve`` answers in this thread.

    Returns:
        Each fit's return value, or the exception it raised, in order. Ctrl-C while serving
        is handed to every fit at its next request (:meth:`FitMeeting.serve`): each ends
        with what it makes of it (a ``KeyboardInterrupt``, or its best point so far).
    """
    meeting = FitMeeting(count, solve)
    outcomes: list[Any] = [None] * count

    def one(k: int) -> None:
        try:
            outcomes[k] = fit(k, meeting)
        except BaseException as exc:  # handed back to the caller's thread
            outcomes[k] = exc
        finally:
            meeting.leave(k)

    threads = [
        threading.Thread(target=one, args=(k,), name=f"warptissue-fit-{k}", daemon=True)
        for k in range(count)
    ]
    for thread in threads:
        thread.start()
    try:
        meeting.serve()
    except KeyboardInterrupt:
        pass  # handed to every fit: their outcomes say what they made of it
    finally:
        for thread in threads:
            thread.join()
    return outcomes
