"""GuardedLifecycleNode: the base class of every lifecycle node of the project.

rclpy's LifecycleNode (Jazzy wheel) raises RCLError "Transition is not registered" for a
transition that is not possible in the current state (activate before configure, configure
twice, cleanup while active, ...). From the change_state service that exception escapes the
executor and kills the node's process; from trigger_*() it reaches the caller. This class
checks every request against the transitions available in the current state first:
- a request that is not possible is refused and logged (warning): the service answers
  `success: false`, trigger_*() returns FAILURE; the node stays in its state and keeps running;
- a transition callback that raises is logged (error) and the transition ends as ERROR (rclpy
  then runs on_error), instead of rclpy's silent ERROR.
It also forwards a plain-Python algorithm's logging to the node's logger on request
(forward_python_logging), until the node is destroyed, and keeps the first failure of the
node's link (fail_link, amr_common.plugins.link_failure): logged once, kept in `link_failure` for
the run scripts, which end the run there (first_link_failure).

The lifecycle shape every node of the project shares is here once:
- `is_active` is True from activate to deactivate (or shutdown): the node's callbacks drop
  their input while it is False;
- cleanup and shutdown call `release()`, which a node overrides to destroy what its on_configure
  created (and which it may also call itself when configure fails half-way).
A node overrides on_configure, release() and whatever else its lifecycle needs (calling super()
in on_activate/on_deactivate/on_cleanup/on_shutdown, as with rclpy's LifecycleNode).
"""
from __future__ import annotations

import logging
import math
import time
from typing import Any, Callable

from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from amr_common.plugins.link_failure import LinkFailure, link_call
from amr_common.python_logging import forward_to_ros_logger

_SHUTDOWN_TRANSITIONS = (Transition.TRANSITION_UNCONFIGURED_SHUTDOWN,
                         Transition.TRANSITION_INACTIVE_SHUTDOWN,
                         Transition.TRANSITION_ACTIVE_SHUTDOWN)


class GuardedLifecycleNode(LifecycleNode):
    """A LifecycleNode that refuses (and logs) out-of-order transitions instead of raising.

    Every lifecycle node of the project inherits from it (SimulatorNode, WallFollowerNode,
    OdometryNode, ...). The change_state service answers `success: false` for a transition that
    is not possible in the current state, trigger_configure/activate/deactivate/cleanup/shutdown
    return TransitionCallbackReturn.FAILURE for one, and a transition callback that raises is
    logged with its exception. The default callbacks keep `is_active` and call `release()` on
    cleanup and shutdown; by themselves they send nothing on the way down. See the module
    docstring.
    """

    def __init__(self, node_name: str, **kwargs) -> None:
        """Create the node as rclpy's LifecycleNode does, with guarded lifecycle services."""
        super().__init__(node_name, **kwargs)
        # rclpy registered the on_* callbacks by state id: log what they raise.
        for state_id, callback in list(self._callbacks.items()):
            self._callbacks[state_id] = self._logging_callback(callback)
        service = getattr(self, "_service_change_state", None)
        if service is not None:  # None when created without the communication interface
            service.callback = self._on_change_state_request
        self._log_forwardings: list[Callable[[], None]] = []
        self._active = False
        self._last_logged: dict[str, float] = {}  # warn_every: kind -> monotonic time
        # The first failure of the node's link (kept across transitions: the run failed).
        self.link_failure: LinkFailure | None = None

    def fail_link(self, failure: LinkFailure, time_s: float | None = None,
                  spec: str | None = None, then: str = "") -> None:
        """Keep the first failure of this node's link and log it once (an error).

        `time_s`, `spec`: when and which class, where the failure does not say; `then`: what
        the node does from now on (e.g. "commanding zero"). Later failures are not logged:
        the node no longer uses the link.
        """
        if self.link_failure is not None:
            return
        self.link_failure = failure.placed(time_s, spec)
        self.get_logger().error(f"{self.link_failure}" + (f"; {then}" if then else "")
                                + " (the run fails)")

    def use_link(self, link: str, member: str, function: Callable[..., Any], *args: Any,
                 spec: str | None = None, allowed: tuple[type[BaseException], ...] = (),
                 check: Callable[[Any], Any] | None = None, time_s: float | None = None,
                 then: str = "") -> Any:
        """function(*args), a call of the node's link (`member` names it), through `check`.

        What it raises (except `allowed`) or what `check` refuses (a LinkFailure) is the link's
        failure (fail_link, with `spec`, `time_s` and `then`); None is returned then, and at
        once from then on: the link is not called again. A caller tells a failure from a None
        result by `link_failure`.
        """
        if self.link_failure is not None:
            return None
        try:
            out = link_call(link, member, function, *args, allowed=allowed)
            return out if check is None else check(out)
        except LinkFailure as failure:
            self.fail_link(failure, time_s, spec, then)
            return None

    def warn_every(self, kind: str, text: str, period_s: float = 2.0,
                   error: bool = False) -> bool:
        """Log `text` (a warning, or an error) unless one of this `kind` was logged < period_s ago.

        rclpy's throttle_duration_sec keys on the call site: a helper that logs every kind from
        one line would let one kind silence the others. True if it was logged.
        """
        now = time.monotonic()
        if now - self._last_logged.get(kind, -math.inf) < period_s:
            return False
        self._last_logged[kind] = now
        if error:  # (rclpy refuses two severities from one call site)
            self.get_logger().error(text)
        else:
            self.get_logger().warning(text)
        return True

    # --- the shared lifecycle shape ----------------------------------------------------------
    @property
    def is_active(self) -> bool:
        """True from activate until deactivate or shutdown: input is processed."""
        return self._active

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable the lifecycle publishers; `is_active` becomes True."""
        result = super().on_activate(state)
        self._active = True
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """`is_active` becomes False, then the lifecycle publishers are disabled.

        What on_configure created stays for a later activate.
        """
        self._active = False
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release what on_configure created (`release()`); back to unconfigured.

        A failure of the link goes with it: the next configure builds the link anew.
        """
        self.release()
        self.link_failure = None
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """From any state (Ctrl-C included): `is_active` becomes False, then `release()`."""
        self._active = False
        self.release()
        return TransitionCallbackReturn.SUCCESS

    def release(self) -> None:
        """Destroy what on_configure created (nothing here); a node overrides it.

        Called by on_cleanup and on_shutdown; must be safe to call again and on a node that
        was never configured.
        """

    def forward_python_logging(self, logger_name: str,
                               record_filter: logging.Filter | None = None) -> Callable[[], None]:
        """Send Python logger `logger_name`'s records to this node's logger.

        For the node's plain-Python algorithm (its warnings then reach rosout and the node's
        log), or a library's; `record_filter` as forward_to_ros_logger's. Returns a function
        that stops the forwarding; destroy_node() stops it too.
        """
        stop = forward_to_ros_logger(logger_name, self.get_logger(), record_filter)
        self._log_forwardings.append(stop)

        def stop_once() -> None:
            if stop in self._log_forwardings:
                self._log_forwardings.remove(stop)
                stop()
        return stop_once

    def destroy_node(self) -> None:
        """Stop the Python log forwarding, then destroy the node as rclpy does."""
        for stop in list(self._log_forwardings):
            stop()
        self._log_forwardings.clear()
        super().destroy_node()

    # --- requests from code ------------------------------------------------------------------
    def trigger_configure(self) -> TransitionCallbackReturn:
        """Configure if the node is unconfigured; else refuse (logged) with FAILURE."""
        return self._guarded(Transition.TRANSITION_CONFIGURE)

    def trigger_cleanup(self) -> TransitionCallbackReturn:
        """Clean up if the node is inactive; else refuse (logged) with FAILURE."""
        return self._guarded(Transition.TRANSITION_CLEANUP)

    def trigger_activate(self) -> TransitionCallbackReturn:
        """Activate if the node is inactive; else refuse (logged) with FAILURE."""
        return self._guarded(Transition.TRANSITION_ACTIVATE)

    def trigger_deactivate(self) -> TransitionCallbackReturn:
        """Deactivate if the node is active; else refuse (logged) with FAILURE."""
        return self._guarded(Transition.TRANSITION_DEACTIVATE)

    def trigger_shutdown(self) -> TransitionCallbackReturn:
        """Shut down from any primary state; refuse (logged) with FAILURE once finalized."""
        for transition_id in _SHUTDOWN_TRANSITIONS:
            if self._available_label(transition_id) is not None:
                return self._guarded(transition_id)
        return self._refuse("shutdown")

    # --- requests from the change_state service ----------------------------------------------
    def _on_change_state_request(self, request: ChangeState.Request,
                                 response: ChangeState.Response) -> ChangeState.Response:
        transition_id = request.transition.id
        label = request.transition.label
        if label:  # as rclpy: a label wins over the id
            matching = [t[0] for t in self._state_machine.available_transitions if t[1] == label]
            if not matching:
                self._refuse(label)
                response.success = False
                return response
            transition_id = matching[0]
        response.success = self._guarded(transition_id) == TransitionCallbackReturn.SUCCESS
        return response

    # --- the guard ---------------------------------------------------------------------------
    def current_state_label(self) -> str:
        """The current state's label, e.g. 'unconfigured', 'active' or 'finalized'."""
        return self._state_machine.current_state[1]

    def _available_label(self, transition_id: int) -> str | None:
        for available in self._state_machine.available_transitions:
            if available[0] == transition_id:
                return available[1]
        return None

    def _guarded(self, transition_id: int) -> TransitionCallbackReturn:
        label = self._available_label(transition_id)
        if label is None:
            return self._refuse(_TRANSITION_LABELS.get(transition_id, f"id {transition_id}"))
        trigger = {
            Transition.TRANSITION_CONFIGURE: super().trigger_configure,
            Transition.TRANSITION_CLEANUP: super().trigger_cleanup,
            Transition.TRANSITION_ACTIVATE: super().trigger_activate,
            Transition.TRANSITION_DEACTIVATE: super().trigger_deactivate,
        }.get(transition_id, super().trigger_shutdown)
        try:
            return trigger()
        except Exception as exc:  # never let a transition take the process down
            self._log_error(f"lifecycle transition '{label}' failed: {exc!r}")
            return TransitionCallbackReturn.ERROR

    def _refuse(self, label: str) -> TransitionCallbackReturn:
        state = self.current_state_label()
        possible = [t[1] for t in self._state_machine.available_transitions]
        self._log_refusal(
            f"lifecycle request '{label}' refused: it is not possible in state '{state}' "
            f"(possible: {', '.join(possible) if possible else 'none'}); staying '{state}'")
        return TransitionCallbackReturn.FAILURE

    def _logging_callback(self, callback: Callable[[LifecycleState], TransitionCallbackReturn]
                          ) -> Callable[[LifecycleState], TransitionCallbackReturn]:
        def logged(state: LifecycleState) -> TransitionCallbackReturn:
            try:
                return callback(state)
            except Exception as exc:
                self._log_error(f"{callback.__name__} raised {exc!r}: transition ends in ERROR")
                raise  # rclpy turns it into ERROR and runs on_error
        return logged

    # Separate methods so tests can observe what is logged.
    def _log_refusal(self, text: str) -> None:
        self.get_logger().warning(text)

    def _log_error(self, text: str) -> None:
        self.get_logger().error(text)


_TRANSITION_LABELS = {Transition.TRANSITION_CONFIGURE: "configure",
                      Transition.TRANSITION_CLEANUP: "cleanup",
                      Transition.TRANSITION_ACTIVATE: "activate",
                      Transition.TRANSITION_DEACTIVATE: "deactivate",
                      **{t: "shutdown" for t in _SHUTDOWN_TRANSITIONS}}


def first_link_failure(nodes) -> LinkFailure | None:
    """The first link failure among `nodes` (those without the attribute count as none)."""
    return next((n.link_failure for n in nodes if getattr(n, "link_failure", None) is not None),
                None)


__all__ = ["GuardedLifecycleNode", "first_link_failure"]
