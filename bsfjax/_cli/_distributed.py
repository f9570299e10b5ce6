"""The start-up of a multi-process run (``--coordinator/--num-processes/--process-id``, or a
SLURM or Open MPI job) and of JAX's backend: bounded waits, and one error line for each way
they can fail."""

from __future__ import annotations

import os
import sys

#: Environment variables of the launchers whose cluster ``jax.distributed.initialize()``
#: detects by itself: (variable holding the process count, launcher).
_CLUSTER_SIZE_VARS = (("SLURM_NTASKS", "SLURM"), ("OMPI_COMM_WORLD_SIZE", "Open MPI"))
#: Seconds ``jax.distributed`` may take to start (``--timeout``): JAX's own default is 300.
DEFAULT_TIMEOUT = 90


def check_coordinator(text: str, error) -> tuple[str, int]:
    """``--coordinator`` as ``HOST:PORT`` (an IPv6 host in brackets), checked before anything:
    ``garbage`` or ``host:abc`` reached gRPC as they were (a traceback, or a segfault)."""
    host, sep, port = text.rpartition(":")
    bare = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if (not sep or not bare or not port.isdigit() or not 1 <= int(port) <= 65535
            or any(c.isspace() or c in "/[]" for c in bare) or (":" in bare and bare == host)):
        raise error(f"--coordinator must be HOST:PORT with a port in [1, 65535] (an IPv6 host "
                    f"in brackets: [::1]:1234), got {text!r}")
    return bare, int(port)


def _initialize_distributed(args, error) -> None:
    """``jax.distributed`` from the flags, or from the cluster's environment without them.
    Start-up waits at most ``--timeout`` seconds; a coordinator that cannot be reached or a
    peer that does not come is one error line (exit status 2), not XLA's abort."""
    flags = (args.coordinator, args.num_processes, args.process_id)
    timeout = getattr(args, "timeout", None)
    timeout = DEFAULT_TIMEOUT if timeout is None else timeout
    if not isinstance(timeout, int) or timeout < 1:
        raise error(f"--timeout must be an integer >= 1 (seconds), got {timeout}")
    if any(f is not None for f in flags):
        if any(f is None for f in flags):
            raise error("--coordinator, --num-processes and --process-id go together")
        check_coordinator(args.coordinator, error)
        if args.num_processes < 1 or not 0 <= args.process_id < args.num_processes:
            raise error(f"--process-id must be in [0, {args.num_processes}) and --num-processes "
                        f">= 1, got {args.process_id} and {args.num_processes}")
        kwargs = dict(coordinator_address=args.coordinator, num_processes=args.num_processes,
                      process_id=args.process_id)
        where = (f"process {args.process_id} of {args.num_processes}, coordinator "
                 f"{args.coordinator}")
    else:
        launcher = next((name for var, name in _CLUSTER_SIZE_VARS
                         if os.environ.get(var, "1").isdigit() and int(os.environ.get(var, "1")) > 1),
                        None)
        if launcher is None:
            return
        kwargs = {}  # jax.distributed finds the coordinator and ranks in the environment
        where = f"{launcher} job"
        print(f"bsfjax: {launcher} job detected: initializing jax.distributed", file=sys.stderr)
    import jax

    jax.config.update("jax_cpu_collectives_implementation", "gloo")  # CPU processes too
    try:
        with _no_abort_on_start_up():
            jax.distributed.initialize(initialization_timeout=timeout, **kwargs)
    except (RuntimeError, ValueError) as exc:
        why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        why = "" if "bad_cast" in why else f" ({why})"
        raise error(f"jax.distributed did not start within --timeout {timeout} s ({where}): "
                    f"the coordinator cannot be reached or a process did not join{why}") from None


class _no_abort_on_start_up:
    """While ``jax.distributed.initialize`` connects, give its client an error callback:
    without one XLA ends the process (``LOG(QFATAL)``, a C++ stack) when the start-up times
    out; with one the failure comes back as an exception.  (jaxlib cannot hand the error's
    status to Python: the call raises a ``RuntimeError`` of its own, which is all we need.)"""

    def __enter__(self):
        try:
            from jax._src.lib import _jax
        except ImportError:  # pragma: no cover - another jaxlib layout: XLA's default
            self.mod = None
            return self
        self.mod, self.real = _jax, getattr(_jax, "get_distributed_runtime_client", None)
        if self.real is not None:
            real = self.real

            def client(*a, **kw):
                try:
                    return real(*a, **dict(kw, missed_heartbeat_callback=lambda *_: None))
                except TypeError:  # a jaxlib without the argument: its own behaviour
                    return real(*a, **kw)

            _jax.get_distributed_runtime_client = client
        return self

    def __exit__(self, *exc):
        if self.mod is not None and self.real is not None:
            self.mod.get_distributed_runtime_client = self.real
        return False


def check_backend(error) -> None:
    """JAX's backend, started now so that a platform that cannot start (``JAX_PLATFORMS=cuda``
    on a machine without CUDA) is one error line, not a traceback."""
    import jax

    try:
        jax.devices()
    except (RuntimeError, AssertionError) as exc:  # (JAX's assert: no platform started)
        first = (str(exc).strip().splitlines()[0] if str(exc).strip() else
                 "none of its platforms is available on this machine")
        raise error(f"JAX cannot start its backend (JAX_PLATFORMS="
                    f"{os.environ.get('JAX_PLATFORMS', '')!r}): {first}") from None
