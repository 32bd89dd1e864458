"""Sound cues: short tones generated with numpy, played through pygame's mixer.

Silence is always an option: :class:`Sounds` is muted when asked, when SDL has no audio device
(``SDL_AUDIODRIVER=dummy``, a server without sound) or when the mixer cannot start; it never
raises. The mixer is tried once per process, and what the sound libraries print while it starts
(ALSA's eight lines per try on a machine without a sound card) goes to the debug log, not the
terminal. Nothing is opened at import.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile

import numpy as np
import pygame

from game.exergames.session import Cue

log = logging.getLogger(__name__)

RATE_HZ = 22050

#: Cue -> notes (frequency Hz, seconds): a rising chime for a collected target, a soft low tone
#: for a miss, two tones for a pause and back.
NOTES: dict[Cue, tuple[tuple[float, float], ...]] = {
    Cue.COLLECTED: ((659.3, 0.08), (880.0, 0.08), (1318.5, 0.16)),
    Cue.MISSED: ((220.0, 0.22),),
    Cue.NEW_TARGET: ((523.3, 0.06),),
    Cue.PAUSED: ((392.0, 0.12), (293.7, 0.18)),
    Cue.RESUMED: ((293.7, 0.10), (392.0, 0.14)),
    Cue.LEVEL_UP: ((523.3, 0.08), (659.3, 0.08), (784.0, 0.08), (1046.5, 0.18)),
    Cue.LEVEL_DOWN: ((392.0, 0.1), (329.6, 0.16)),
    Cue.READY: ((523.3, 0.1), (784.0, 0.16)),
    Cue.DONE: ((523.3, 0.12), (659.3, 0.12), (784.0, 0.12), (1046.5, 0.3)),
}


#: Why the mixer could not start in this process ("" : not tried yet, or it started).
_mixer_failed = ""


@contextlib.contextmanager
def _stderr_to_log():
    """Send what C libraries write to the process's stderr (file descriptor 2) to the debug log."""
    try:
        saved = os.dup(2)
    except OSError:   # no stderr to redirect
        yield
        return
    with tempfile.TemporaryFile() as sink:
        sys.stderr.flush()
        os.dup2(sink.fileno(), 2)
        try:
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            text = sink.read().decode("utf-8", "replace").strip()
            if text:
                log.debug("the sound libraries said: %s", " | ".join(text.splitlines()))


def tone(notes, rate_hz: int = RATE_HZ, volume: float = 0.35) -> np.ndarray:
    """(N, 2) int16 stereo samples of ``notes`` ((Hz, s) pairs) with soft attack and decay."""
    parts = []
    for freq, dur in notes:
        t = np.arange(int(rate_hz * dur)) / rate_hz
        env = np.minimum(1.0, t / 0.01) * np.exp(-3.0 * t / max(dur, 1e-3))
        wave = np.sin(2 * np.pi * freq * t) + 0.25 * np.sin(4 * np.pi * freq * t)
        parts.append(wave * env)
    mono = np.concatenate(parts) if parts else np.zeros(1)
    pcm = (np.clip(mono * volume, -1.0, 1.0) * 32767).astype(np.int16)
    return np.ascontiguousarray(np.stack([pcm, pcm], axis=1))


class Sounds:
    """The cue player.

    Args:
        mute: stay silent.
    """

    def __init__(self, mute: bool = False) -> None:
        self.enabled = False
        self._sounds = {}
        global _mixer_failed
        if mute or os.environ.get("SDL_AUDIODRIVER", "") == "dummy" or _mixer_failed:
            return
        try:
            if not pygame.mixer.get_init():
                with _stderr_to_log():
                    pygame.mixer.init(frequency=RATE_HZ, size=-16, channels=2)
            freq, _, channels = pygame.mixer.get_init()
            for cue, notes in NOTES.items():
                samples = tone(notes, freq)
                if channels == 1:
                    samples = np.ascontiguousarray(samples[:, 0])
                self._sounds[cue] = pygame.sndarray.make_sound(samples)
            self.enabled = True
        except Exception as exc:  # noqa: BLE001 - any mixer failure means silence, never a crash
            _mixer_failed = str(exc) or type(exc).__name__
            log.info("no sound: %s", _mixer_failed)
            self._sounds = {}

    def play(self, cue: Cue) -> None:
        sound = self._sounds.get(cue) if self.enabled else None
        if sound is not None:
            try:
                sound.play()
            except Exception as exc:  # noqa: BLE001
                log.info("sound failed, going silent: %s", exc)
                self.enabled = False
