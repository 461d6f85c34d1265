"""Asking the operator (mission language v2): ``ask`` stands still until a yes or no comes, from wherever it comes.

:class:`OperatorQuestions` is the run's board of questions: the ``ask`` leaf
opens one, and every operator channel may answer it: a script
(``--answer ID=yes``, the harness's ``answers=``, answered as soon as the
question opens), the terminal, the web console, or the timeout with its
default. The question and the answer (with who gave it) are events, so they
are in the run's summary and recording.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Optional

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext
from beastbt.core.units import format_quantity

CHOICES = ("yes", "no")


def choice_of(value: object) -> Optional[str]:
    """``yes``/``no`` from what an author or operator wrote (YAML's true/false, y/n, any case), else None."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    text = str(value).strip().lower()
    return {"yes": "yes", "y": "yes", "true": "yes", "no": "no", "n": "no", "false": "no"}.get(text)


@dataclass
class Question:
    """An open question: ``id``, ``text``, its ``choices``, when it was asked (clock s)."""

    id: str
    text: str
    asked_s: float
    choices: tuple[str, ...] = CHOICES


class OperatorQuestions:
    """The questions of one run and their answers; ``scripted``: answers given before the run (id -> yes/no)."""

    def __init__(self, ctx_events: object, scripted: Optional[Mapping[str, str]] = None) -> None:
        self.events = ctx_events
        self.scripted = {k: v for k, v in (scripted or {}).items()}
        self.open: dict[str, Question] = {}
        self.answers: dict[str, tuple[str, str]] = {}
        """id -> (yes|no, who: script, terminal, console, timeout)."""

    def ask(self, question: Question) -> None:
        """Open ``question`` (forgetting an earlier answer to the same id); a scripted answer comes at once."""
        self.answers.pop(question.id, None)
        self.open[question.id] = question
        self.events.add("ask", f"{question.id}: {question.text} ({' / '.join(question.choices)})")  # type: ignore[attr-defined]
        if question.id in self.scripted:
            self.answer(question.id, self.scripted[question.id], "script")

    def answer(self, question_id: str, choice: object, who: str) -> bool:
        """Answer an open question; False (nothing changes) when it is not open or the choice is not yes/no."""
        value = choice_of(choice)
        if question_id not in self.open or value is None:
            return False
        del self.open[question_id]
        self.answers[question_id] = (value, who)
        self.events.add("answer", f"{question_id}: {value} (by {who})")  # type: ignore[attr-defined]
        return True

    def answer_of(self, question_id: str) -> Optional[str]:
        """The answer given to ``question_id`` (yes/no), or None."""
        got = self.answers.get(question_id)
        return got[0] if got else None

    def current(self) -> Optional[Question]:
        """The question waiting longest for an answer, or None."""
        return min(self.open.values(), key=lambda q: q.asked_s) if self.open else None


class AskOperator(BeastBehaviour):
    """Stand still with a question open until it is answered.

    SUCCESS once answered (by anyone, or by the timeout with a default);
    FAILURE when the timeout passes without a default. RUNNING meanwhile,
    commanding zero velocity. The question closes if the step is halted.
    """

    WRITES = ("cmd_mission",)

    def __init__(self, name: str, ctx: MissionContext, question_id: str, text: str, timeout_s: Optional[float],
                 default: Optional[str]) -> None:
        super().__init__(name, ctx)
        self.question_id = question_id
        self.text = text
        self.timeout_s = timeout_s
        self.default = default
        self.asked_s = 0.0

    def questions(self) -> OperatorQuestions:
        board = self.ctx.services.questions
        if board is None:  # a run built without one: questions go to the event log, and only a timeout answers
            board = self.ctx.services.questions = OperatorQuestions(self.ctx.events)
        return board

    def initialise(self) -> None:
        self.asked_s = self.now()
        self.questions().ask(Question(self.question_id, self.text, self.asked_s))

    def update(self) -> Status:
        board = self.questions()
        self.command(0.0, 0.0)
        answer = board.answer_of(self.question_id)
        if answer is not None:
            self.feedback_message = f"answered {answer}"
            return Status.SUCCESS
        if self.timeout_s is not None and self.now() - self.asked_s >= self.timeout_s:
            if self.default is not None:
                board.answer(self.question_id, self.default, "timeout")
                self.feedback_message = f"no answer in {format_quantity(self.timeout_s, 'duration')}: {self.default}"
                return Status.SUCCESS
            return self.fail(f"no answer to '{self.text}' in {format_quantity(self.timeout_s, 'duration')}")
        self.feedback_message = f"waiting for an answer: {self.text}"
        return Status.RUNNING

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID:
            self.questions().open.pop(self.question_id, None)


__all__ = ["OperatorQuestions", "Question", "AskOperator", "choice_of", "CHOICES"]
