"""The studio's people's colours by name: albedos in linear RGB (0..1), none of them blue.

Every colour passes the chroma key as person: its 8-bit b − max(r, g) stays below 14 under any exposure
and white balance studio/cases.py draws (the key takes > 25 for blue screen; tests/test_cases.py checks).
"""

SKIN_TONES = {   # light to dark
    'pale': (0.85, 0.62, 0.52), 'light': (0.75, 0.52, 0.42), 'medium': (0.62, 0.40, 0.30),
    'tan': (0.48, 0.30, 0.20), 'brown': (0.38, 0.22, 0.13), 'dark': (0.28, 0.16, 0.10), 'deep': (0.15, 0.08, 0.05),
}
SHIRTS = {
    'red': (0.55, 0.12, 0.10), 'green': (0.12, 0.35, 0.12), 'grey': (0.30, 0.30, 0.30), 'white': (0.80, 0.80, 0.78),
    'yellow': (0.70, 0.55, 0.08), 'black': (0.03, 0.03, 0.035), 'light grey': (0.55, 0.55, 0.55),
    'beige': (0.55, 0.45, 0.32), 'orange': (0.75, 0.25, 0.05), 'pink': (0.75, 0.30, 0.40),
    'maroon': (0.25, 0.03, 0.05), 'purple': (0.30, 0.08, 0.28), 'teal': (0.04, 0.28, 0.25), 'olive': (0.25, 0.25, 0.06),
}
RED_SHIRTS = ('red', 'maroon')  # what markers/detection.red_mask takes for markers (not orange: hue 27°; pink: S 0.34)
TROUSER_COLOURS = {
    'dark': (0.08, 0.08, 0.09), 'black': (0.025, 0.025, 0.028), 'grey': (0.20, 0.20, 0.20),
    'faded denim': (0.11, 0.12, 0.13), 'khaki': (0.40, 0.33, 0.18), 'brown': (0.20, 0.11, 0.06),
    'olive': (0.15, 0.16, 0.07), 'white': (0.70, 0.70, 0.68),
}
HAIR_COLOURS = {
    'dark': (0.06, 0.04, 0.03), 'black': (0.025, 0.02, 0.018), 'brown': (0.15, 0.08, 0.04),
    'auburn': (0.30, 0.10, 0.04), 'blond': (0.55, 0.40, 0.18), 'grey': (0.35, 0.35, 0.35),
}
# cropped: a high hairline; short: a cap over the crown and the back of the head; long: and a shell to the shoulders.
HAIR_LENGTHS = ('cropped', 'short', 'long')
