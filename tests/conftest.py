"""Settings shared by every test."""

import os

# render_mode="human" opens a pygame window; the dummy video driver makes that headless.
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
