"""The rotation game's river on the screen: water flowing down, a sailing boat the rotation steers,
gates (two buoys) drifting down to it.

Seen from above, the river runs from the top of its rectangle down past the boat near the bottom;
its banks are the ends of the patient's measured rotation range (:mod:`game.exergames.river`).
The water and the banks are bands of flat colour (opaque fills: llvmpipe, the CPU rasterizer, paints
a third of the window cheapest that way; a textured tile cost ~1.5 ms more CPU per frame) with ripples
and bushes carried down by the flow; the ripples and the boat (turned to a few headings) are drawn
once with pygame when the scene opens. A frame costs seven fills (one draw), a textured quad and a
few dozen shapes of the canvas batch.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
import pygame

from game.exergames.river import River, gate_distance
from game.gfx.canvas import surface_to_texture
from game.gfx import theme

GOOD = (120, 220, 120)
WATER = (46, 128, 178)
WATER_DEEP = (34, 104, 156)
BANK = (86, 150, 84)
BANK_DARK = (62, 118, 64)
SAND = (214, 196, 140)
RIPPLE = (150, 200, 230)
#: Headings the boat is drawn at (degrees, + turns the bow to the right).
HEADINGS_DEG = tuple(range(-24, 25, 6))
#: Share of the river's width that is bank on each side.
BANK_SHARE = 0.09
#: Pixels per second the water flows between gates (at 1280x720).
IDLE_FLOW_PX_S = 60.0


def _boat_surface(length_px: int, colour) -> pygame.Surface:
    """A sailing boat seen from above, bow up: a wooden hull, a white sail filled by the wind, a coloured flag."""
    w, h = round(length_px * 0.66), length_px
    surf = pygame.Surface((w, h), pygame.SRCALPHA)
    surf.fill((120, 80, 40, 0))

    def pts(rel):
        return [(w * a, h * b) for a, b in rel]

    shadow = pygame.Surface((w, h), pygame.SRCALPHA)
    pygame.draw.polygon(shadow, (0, 0, 0, 70), pts([(0.56, 0.04), (0.90, 0.34), (0.90, 0.80), (0.74, 1.0),
                                                    (0.38, 1.0), (0.22, 0.80), (0.22, 0.34)]))
    surf.blit(shadow, (0, 0))
    pygame.draw.polygon(surf, (96, 60, 30), pts([(0.5, 0.0), (0.84, 0.30), (0.86, 0.78), (0.70, 0.97),
                                                 (0.30, 0.97), (0.14, 0.78), (0.16, 0.30)]))
    pygame.draw.polygon(surf, (190, 136, 80), pts([(0.5, 0.07), (0.75, 0.31), (0.77, 0.76), (0.64, 0.90),
                                                   (0.36, 0.90), (0.23, 0.76), (0.25, 0.31)]))
    for k in range(4):      # deck planks
        y = h * (0.36 + 0.13 * k)
        pygame.draw.line(surf, (160, 110, 62), (w * 0.25, y), (w * 0.75, y), max(1, round(h / 60)))
    # the sail: a white bulge from the mast to the boom, pushed to one side by the wind
    pygame.draw.polygon(surf, (250, 250, 246), pts([(0.5, 0.30), (0.86, 0.42), (0.98, 0.58), (0.86, 0.72),
                                                    (0.5, 0.80)]))
    pygame.draw.polygon(surf, (196, 200, 206), pts([(0.5, 0.30), (0.86, 0.42), (0.98, 0.58), (0.86, 0.72),
                                                    (0.5, 0.80)]), max(1, round(h / 45)))
    pygame.draw.line(surf, (70, 46, 26), (w * 0.5, h * 0.30), (w * 0.5, h * 0.82), max(2, round(h / 30)))  # boom
    pygame.draw.polygon(surf, tuple(colour), pts([(0.5, 0.30), (0.26, 0.22), (0.5, 0.15)]))               # flag
    pygame.draw.circle(surf, (60, 40, 22), (round(w * 0.5), round(h * 0.30)), max(2, round(w * 0.07)))  # mast
    return surf


@dataclass(frozen=True)
class _RiverLook:
    """The river's rectangle as bands across it and features on it, in pixels of the rectangle.

    Attributes:
        bands: (x0, x1, colour) from left to right: bank, sand, shallow water, deep water and back.
        ripples: (x, y, mask) white arcs on the water (masks made once, drawn tinted).
        bushes: (x, y, radius) dark green discs on the banks.
        height: the rectangle's height: the features repeat every ``height`` pixels down the river.
    """

    bands: tuple
    ripples: tuple
    bushes: tuple
    height: float


def _river_look(w: int, h: int, seed: int = 5) -> _RiverLook:
    """Banks and water of the river's rectangle; its features repeat vertically (they wrap top to bottom)."""
    rng = np.random.default_rng(seed)
    bank = round(w * BANK_SHARE)
    shallow = round(w * 0.06)     # deeper water away from the banks
    bands = ((0, bank - 5, BANK), (bank - 5, bank, SAND), (bank, bank + shallow, WATER),
             (bank + shallow, w - bank - shallow, WATER_DEEP), (w - bank - shallow, w - bank, WATER),
             (w - bank, w - bank + 5, SAND), (w - bank + 5, w, BANK))
    ripples = []
    for _ in range(max(8, h // 40)):
        x = rng.uniform(bank + 14, w - bank - 40)
        y = rng.uniform(0, h)
        length = rng.uniform(16, 34)
        mask = pygame.Surface((math.ceil(length) + 1, 11), pygame.SRCALPHA)
        pygame.draw.arc(mask, (255, 255, 255), (x % 1.0, 0, length, 10), 0.3, math.pi - 0.3, 2)
        ripples.append((math.floor(x), y, mask))
    bushes = []
    for side in (0, 1):
        for _ in range(max(4, h // 90)):
            x = rng.uniform(4, bank - 6) if side == 0 else rng.uniform(w - bank + 6, w - 4)
            y = rng.uniform(0, h)
            r = rng.uniform(5, min(11, bank * 0.35))
            bushes.append((float(round(x)), y, float(round(r))))
    return _RiverLook(bands, tuple(ripples), tuple(bushes), float(h))


class RiverView:
    """Draws the river of a rotation game session into a rectangle of the window.

    Args:
        ctx: the GL context (textures are made once, released by :meth:`release`).
        rect: (x, y, w, h) window pixels of the river.
        scale: the window's scale against 1280x720.
        colour: the game's colour (gates, the boat's stripe).
    """

    def __init__(self, ctx, rect, scale: float, colour) -> None:
        self.rect = tuple(float(v) for v in rect)
        self.scale = scale
        self.colour = tuple(colour)
        x, y, w, h = self.rect
        self.ctx = ctx
        self.look = _river_look(round(w), round(h))
        self.boat_len = 80.0 * scale
        boat = _boat_surface(round(self.boat_len), self.colour)
        self.boat_half_w = boat.get_width() / 2.0
        self.boats = {}
        for heading in HEADINGS_DEG:
            turned = pygame.transform.rotozoom(boat, -heading, 1.0)
            self.boats[heading] = (surface_to_texture(ctx, turned), turned.get_size())
        self.bank = w * BANK_SHARE
        self.bow_y = y + h - 150.0 * scale
        self.far_y = y + 40.0 * scale
        self.scroll_px = 0.0
        self.boat_x: float | None = None
        self._heading = 0.0
        self._gate = None            # (target id, distance) of the last frame
        self._ended: deque = deque(maxlen=3)   # (value, size, reached, time ended, y and scroll at the end)
        self._wake: deque = deque(maxlen=14)   # (x, scroll) behind the boat
        self._wake_s = 0.0
        self.gate_px: tuple[float, float] | None = None    # the current gate's centre (tests look there)
        self.boat_px: tuple[float, float] | None = None

    # ------------------------------------------------------------------ geometry
    @property
    def lane_px(self) -> tuple[float, float]:
        """(left, width) of the water the boat's centre moves on (the boat stays off the banks)."""
        x, _, w, _ = self.rect
        edge = self.bank + self.boat_half_w
        return x + edge, w - 2 * edge

    def x_px(self, river: River, rotation_deg: float) -> float:
        left, width = self.lane_px
        return left + river.across(rotation_deg) * width

    def rotation_at_px(self, river: River, x_px: float) -> float:
        """The rotation that puts the boat at window x ``x_px`` (the mouse steering)."""
        left, width = self.lane_px
        return river.rotation_at((x_px - left) / width)

    def half_width_px(self, river: River, degrees: float) -> float:
        """Half the opening of a gate of tolerance ``degrees``: the boat fits between the buoys exactly when
        its centre (the measured rotation) is within the tolerance."""
        return river.width(degrees) * self.lane_px[1] + self.boat_half_w

    def gate_y(self, distance: float) -> float:
        """Window y of a gate ``distance`` ahead of the bow (:func:`game.exergames.river.gate_distance`)."""
        if distance >= 0.0:
            return self.bow_y - distance * (self.bow_y - self.far_y)
        return self.bow_y - distance * self.boat_len

    # ------------------------------------------------------------------ per frame
    def advance(self, dt_s: float, river: River, rotation_deg: float, target, paused: bool) -> None:
        """Move the water with the current gate (or freely between gates) and steer the boat."""
        s = self.scale
        if target is not None:
            d = gate_distance(target)
            key = id(target)
            if self._gate is not None and self._gate[0] == key:
                self.scroll_px += max(0.0, self.gate_y(d) - self.gate_y(self._gate[1]))
            self._gate = (key, d)
        else:
            self._gate = None
            if not paused:
                self.scroll_px += IDLE_FLOW_PX_S * s * dt_s
        if math.isfinite(rotation_deg):
            x = self.x_px(river, rotation_deg)
            if self.boat_x is None:
                self.boat_x = x
            moved = x - self.boat_x
            self.boat_x += moved * min(1.0, dt_s * 12.0)    # a boat glides: no jitter from the readings
            if dt_s > 0:
                rate = moved / max(dt_s, 1e-3) / (40.0 * s)   # px/s -> a heading
                self._heading += (max(-24.0, min(24.0, rate * 6.0)) - self._heading) * min(1.0, dt_s * 6.0)
        self._wake_s += dt_s
        if self.boat_x is not None and self._wake_s > 0.08:
            self._wake_s = 0.0
            self._wake.append((self.boat_x, self.scroll_px))

    def target_ended(self, value_deg: float, size_deg: float, reached: bool, now_s: float) -> None:
        """Remember a gate that was just passed (it sails on behind the boat) or missed (it sinks)."""
        y = self.gate_y(self._gate[1]) if self._gate is not None else self.bow_y
        self._ended.append((value_deg, size_deg, reached, now_s, y, self.scroll_px))

    # ------------------------------------------------------------------ drawing
    def draw(self, c, river: River, session, now_s: float) -> None:
        """The river, the gates, the boat and its labels."""
        x, y, w, h = self.rect
        s = self.scale
        self._draw_water(c)
        # where the arm points now along the river's width, from its ends: "in" and "out" banks
        size = round(theme.SMALL * 0.85 * s)
        out_left = river.side == "left"
        words = ("< out", "in >") if out_left else ("< in", "out >")
        for text, pos, anchor in ((words[0], (x + 10 * s, y + h - 10 * s), "bottomleft"),
                                  (words[1], (x + w - 10 * s, y + h - 10 * s), "bottomright")):
            box = c.measure(text, size)
            bx = pos[0] if anchor == "bottomleft" else pos[0] - box[0]
            c.rect((bx - 6 * s, pos[1] - box[1] - 4 * s, box[0] + 12 * s, box[1] + 8 * s), theme.OVERLAY, radius=8 * s)
            c.text(text, pos, size, theme.TEXT, anchor=anchor)
        for value, size_deg, reached, t0, y_end, scroll0 in list(self._ended):
            age = now_s - t0
            if age > 1.2:
                continue
            fade = max(0.0, 1.0 - age / 1.2)
            yy = y_end + (self.scroll_px - scroll0) if reached else y_end
            self._draw_gate(c, river, value, size_deg, yy, GOOD if reached else theme.TEXT_FAINT,
                            alpha=round(255 * fade), shrink=1.0 if reached else fade)
        t = session.target
        self.gate_px = None
        boat_inside = False
        if t is not None:
            d = gate_distance(t)
            gy = self.gate_y(d)
            value = session.value_now()
            boat_inside = math.isfinite(value) and abs(value - t.target.value_deg) <= t.size
            colour = GOOD if boat_inside else self.colour
            gx = self.x_px(river, t.target.value_deg)
            half = self.half_width_px(river, t.size)
            if not t.arrived:   # the channel the gate will come down: steer into it
                for k in range(1, 12):
                    yy = gy + (self.bow_y - gy) * k / 12
                    for sx in (-1, 1):
                        c.circle((gx + sx * half, yy), 2.5 * s, (255, 255, 255, 90))
            self._draw_gate(c, river, t.target.value_deg, t.size, gy, colour, paused=session.paused)
            self.gate_px = (gx, gy)
            if t.arrived:       # the gate's time left: a bar over it
                left = max(0.0, 1.0 - t.age_s / t.time_limit_s)
                c.rect((gx - half, gy - 40 * s, 2 * half, 7 * s), (0, 0, 0, 90), radius=3 * s)
                c.rect((gx - half, gy - 40 * s, 2 * half * left, 7 * s), (*self.colour, 230), radius=3 * s)
        self._draw_boat(c, boat_inside)

    def _draw_water(self, c) -> None:
        """The banks and the water, the ripples and the bushes moved down by the flow (wrapping)."""
        x, y, w, h = self.rect
        look = self.look
        x0, y0 = round(x), round(y)
        for a, b, colour in look.bands:
            c.fill((x0 + a, y0, b - a, look.height), colour)
        c.clip((x0, y0, round(w), look.height))
        shift = self.scroll_px % look.height
        for rx, ry, mask in look.ripples:
            yy = (ry + shift) % look.height
            for wrap in (0.0, -look.height):     # the part still above the top edge
                if -12.0 < yy + wrap < look.height:
                    c.sprite(("river-ripple", id(mask)), mask, (x0 + rx, y0 + yy + wrap), RIPPLE)
        for bx, by, r in look.bushes:
            yy = (by + shift) % look.height
            for wrap in (0.0, -look.height, look.height):
                if -r < yy + wrap < look.height + r:
                    c.circle((x0 + bx, y0 + yy + wrap), r, BANK_DARK)
        c.clip(None)

    def _draw_gate(self, c, river: River, value_deg: float, size_deg: float, gy: float, colour, *,
                   alpha: int = 255, shrink: float = 1.0, paused: bool = False) -> None:
        s = self.scale
        gx = self.x_px(river, value_deg)
        half = self.half_width_px(river, size_deg)
        a = round(alpha * (0.5 if paused else 1.0))
        for k in range(1, 8):   # the line between the buoys
            c.circle((gx - half + 2 * half * k / 8, gy), 2.5 * s * shrink, (255, 255, 255, round(a * 0.8)))
        for sx in (-1, 1):
            r = 13 * s * shrink
            c.circle((gx + sx * half, gy + 4 * s), r + 3 * s, (0, 0, 0, round(a * 0.25)))
            c.circle((gx + sx * half, gy), r, (*colour[:3], a), border=3 * s, border_colour=(255, 255, 255, a))

    def _draw_boat(self, c, inside: bool) -> None:
        self.boat_px = None
        if self.boat_x is None:
            return
        s = self.scale
        stern = self.bow_y + self.boat_len
        for k, (wx, scroll0) in enumerate(self._wake):   # the wake: foam left behind, carried by the water
            yy = stern + (self.scroll_px - scroll0) - 6 * s
            if yy < self.rect[1] + self.rect[3]:
                c.circle((wx, yy), (3 + 0.4 * (len(self._wake) - k)) * s, (255, 255, 255, 40 + 8 * k))
        heading = min(HEADINGS_DEG, key=lambda hd: abs(hd - self._heading))
        tex, (bw, bh) = self.boats[heading]
        cy = self.bow_y + self.boat_len / 2
        if inside:
            c.circle((self.boat_x, cy), self.boat_len * 0.6, (0, 0, 0, 0), border=4 * s, border_colour=(*GOOD, 200))
        c.texture(tex, (self.boat_x - bw / 2, cy - bh / 2, bw, bh))
        self.boat_px = (self.boat_x, cy)

    def release(self) -> None:
        for tex, _ in self.boats.values():
            tex.release()
        self.boats.clear()
