"""Start the node executables as separate processes and always stop them.

No rclpy here: this module only deals with operating-system processes, DDS
domain ids and environment variables.
"""
from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping, Sequence

#: The node executables of the package (console scripts of setup.py).
NODE_EXECUTABLES = ('master', 'sim_instrument', 'controller')

#: Fast DDS / RTPS port mapping (DDSI-RTPS spec 9.6.1.1): PB + DG * domain_id.
_PORT_BASE = 7400
_DOMAIN_GAIN = 250
#: Largest domain id whose ports stay valid for every participant on Linux.
MAX_DOMAIN_ID = 101


class ProcessError(RuntimeError):
    """A node process could not be started or died early."""


def node_command(name: str) -> list[str]:
    """The command that runs node ``name``: its console script, else ``python -m``.

    The console script next to the running interpreter is preferred (a plain
    ``master`` on the PATH might be someone else's program). The environment
    variable ``GRIP_FORCE_NODE_<NAME>`` (e.g. ``GRIP_FORCE_NODE_SIM_INSTRUMENT``)
    replaces the command, e.g. to run the demo against another build or a
    hardware driver; ``--ros-args ...`` is appended to it.
    """
    override = os.environ.get(f'GRIP_FORCE_NODE_{name.upper()}')
    if override:
        return shlex.split(override)
    script = Path(sys.executable).parent / name
    if script.is_file() and os.access(script, os.X_OK):
        return [str(script)]
    return [sys.executable, '-m', f'grip_force_ros.nodes.{name}']


def ros_args(params_file: str | os.PathLike | None = None,
             overrides: Mapping[str, object] | None = None,
             node_name: str | None = None) -> list[str]:
    """``--ros-args`` for a node: parameter file, then ``-p name:=value`` overrides."""
    out = ['--ros-args']
    if node_name:
        out += ['-r', f'__node:={node_name}']
    if params_file is not None:
        out += ['--params-file', str(params_file)]
    for key, value in (overrides or {}).items():
        out += ['-p', f'{key}:={_ros_literal(value)}']
    return out


def _ros_literal(value: object) -> str:
    """A value as ROS parses it on the command line (YAML)."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (list, tuple)):
        return '[' + ','.join(_ros_literal(v) for v in value) + ']'
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):   # quoted: '' and 'true' / '1.0' stay strings
        return "'" + value.replace("'", "''") + "'"
    return str(value)


def _udp_ports_in_use() -> set[int]:
    try:
        import psutil
        return {c.laddr.port for c in psutil.net_connections(kind='udp') if c.laddr}
    except Exception:  # noqa: BLE001 - psutil missing or not permitted: nothing known
        return set()


def domain_in_use(domain_id: int, ports: set[int] | None = None) -> bool:
    """True if some process has bound a DDS port of ``domain_id`` on this machine."""
    ports = _udp_ports_in_use() if ports is None else ports
    low = _PORT_BASE + _DOMAIN_GAIN * domain_id
    return any(low <= p < low + _DOMAIN_GAIN for p in ports)


def pick_domain_ids(count: int = 1, *, start: int | None = None,
                    candidates: Iterable[int] | None = None,
                    exclude: Iterable[int] = ()) -> list[int]:
    """``count`` ROS domain ids that no process on this machine is using.

    The search starts at a pid-derived id (two runs started together rarely
    pick the same one) and wraps around ``1..MAX_DOMAIN_ID``.

    Raises
    ------
    ProcessError
        If not enough free domains exist.
    """
    ports = _udp_ports_in_use()
    if candidates is None:
        first = (os.getpid() % MAX_DOMAIN_ID) + 1 if start is None else start
        candidates = [((first - 1 + k) % MAX_DOMAIN_ID) + 1 for k in range(MAX_DOMAIN_ID)]
    excluded = set(exclude)
    chosen = []
    for d in candidates:
        if d in excluded or d in chosen or domain_in_use(d, ports):
            continue
        chosen.append(d)
        if len(chosen) == count:
            return chosen
    raise ProcessError(f'no {count} free ROS domain id(s) found')


def ros_environment(domain_id: int, base: Mapping[str, str] | None = None) -> dict[str, str]:
    """Environment for a node: the given domain, loopback discovery unless chosen."""
    env = dict(os.environ if base is None else base)
    env['ROS_DOMAIN_ID'] = str(int(domain_id))
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('PYTHONUNBUFFERED', '1')
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    return env


@dataclass
class NodeProcess:
    """One started node: its name, process and log file."""

    name: str
    popen: subprocess.Popen
    log_path: Path | None

    def alive(self) -> bool:
        return self.popen.poll() is None

    def log_tail(self, lines: int = 15) -> str:
        if not self.log_path or not self.log_path.exists():
            return ''
        text = self.log_path.read_text(errors='replace').splitlines()
        return '\n'.join(text[-lines:])


@dataclass
class ProcessGroup:
    """Processes that run together and are always stopped together.

    Use as a context manager: on exit (normal, exception or Ctrl-C) every
    process gets SIGINT, then ``grace`` seconds, then SIGTERM, then SIGKILL.
    Each process runs in its own session so that a Ctrl-C at the terminal
    reaches only the orchestrator, which then stops the nodes in order.
    """

    env: dict[str, str]
    log_dir: Path | None = None
    grace: float = 3.0
    processes: list[NodeProcess] = field(default_factory=list)

    def start(self, name: str, argv: Sequence[str], *, label: str | None = None) -> NodeProcess:
        """Start ``argv`` (its output goes to ``<log_dir>/<label>.log``)."""
        label = label or name
        log_path = None
        stdout = subprocess.DEVNULL
        if self.log_dir is not None:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            log_path = self.log_dir / f'{label}.log'
            stdout = open(log_path, 'wb')  # noqa: SIM115 - closed below, after Popen dup'ed it
        try:
            popen = subprocess.Popen(list(argv), env=self.env, stdout=stdout,
                                     stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                     start_new_session=True)
        except OSError as exc:
            raise ProcessError(f'cannot start {label}: {exc}') from exc
        finally:
            if stdout is not subprocess.DEVNULL:
                stdout.close()
        proc = NodeProcess(label, popen, log_path)
        self.processes.append(proc)
        return proc

    def check_alive(self, may_finish: tuple[str, ...] = ()) -> None:
        """Raise :class:`ProcessError` naming any process that has exited.

        Processes named in ``may_finish`` may have exited with code 0.
        """
        for p in self.processes:
            code = p.popen.poll()
            if code is not None and not (code == 0 and p.name in may_finish):
                tail = p.log_tail()
                raise ProcessError(f'{p.name} exited with code {code}'
                                   + (f'; last output:\n{tail}' if tail else ''))

    def stop(self) -> dict[str, int | None]:
        """Stop all processes (reverse start order): SIGINT, wait, SIGTERM, SIGKILL.

        Returns
        -------
        dict
            Process label -> exit code.
        """
        running = [p for p in reversed(self.processes) if p.alive()]
        for sig, wait in ((signal.SIGINT, self.grace), (signal.SIGTERM, 2.0),
                          (signal.SIGKILL, 2.0)):
            for p in running:
                _signal_group(p.popen, sig)
            deadline = time.monotonic() + wait
            while running and time.monotonic() < deadline:
                running = [p for p in running if p.alive()]
                if running:
                    time.sleep(0.05)
            if not running:
                break
        return {p.name: p.popen.poll() for p in self.processes}

    def __enter__(self) -> 'ProcessGroup':
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def _signal_group(popen: subprocess.Popen, sig: int) -> None:
    """Send ``sig`` to the process group of ``popen`` (its own session)."""
    try:
        os.killpg(popen.pid, sig)
    except ProcessLookupError:
        pass
    except PermissionError:  # pragma: no cover - not our group after all
        popen.send_signal(sig)
