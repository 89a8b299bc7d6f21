"""Sessions: performers x characters x outputs on one clock.

    from mop.session import load_session, build_session
    config = load_session("sessions/demo.toml")      # frozen, checked SessionConfig
    session = build_session(config)                    # takes, followers, puppets, outputs
    report = session.run()                             # until the takes end (or Ctrl-C)
    print(report.format())

Modules: `config` (the session file), `build` (config -> running parts), `loop` (the clock and
the per-frame work), `feeds` (performer input), `outputs` (video, PNG, OSC), `preview` (the live
web page), `timing` (per-stage timing and the report).
"""
from .config import SessionConfig, SessionError, load_session, parse_session
from .loop import Mode, Session

__all__ = ["SessionConfig", "SessionError", "load_session", "parse_session", "Mode", "Session",
           "build_session", "Overrides"]


def __getattr__(name):
    # build pulls in capture / followers / characters: only when asked for
    if name in ("build_session", "Overrides"):
        from . import build
        return getattr(build, name)
    raise AttributeError(f"module 'mop.session' has no attribute {name!r}")
