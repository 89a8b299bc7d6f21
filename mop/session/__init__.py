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
import lazy_loader

from .config import SessionConfig, SessionError, load_session, parse_session
from .loop import Mode, Session

# build pulls in capture / followers / characters: only when asked for
__getattr__, _, _lazy = lazy_loader.attach(__name__, submod_attrs={
    "build": ["build_session", "Overrides"]})
__all__ = ["SessionConfig", "SessionError", "load_session", "parse_session", "Mode", "Session",
           *_lazy]
