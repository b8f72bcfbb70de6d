"""Settings shared by every test."""

import os
import signal

# render_mode="human" opens a pygame window; the dummy video driver makes that headless.
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")

# Several tests interrupt a child process with SIGINT (Ctrl-C) and check what it saved. A
# shell without job control starts background jobs with SIGINT ignored, and an ignored signal
# stays ignored across exec, so a suite started as `make test &` would hand its children a
# deaf ear. Restoring Python's handler here makes the children's disposition the default.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
