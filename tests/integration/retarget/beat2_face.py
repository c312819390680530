#!/usr/bin/env python3
"""A viseme file (the V.json of `kinemo animate --visemes`, common/face/face_json.h)
made from what BEAT2 captured with a take's speech, for the face tests of
`kinemo retarget --visemes`: the OVR viseme of the forced-aligned phone under
each frame (the TextGrid's phone tier; ARPAbet -> OVR as common/face/visemes.h
classes them), the captured jaw opening (the SMPL-X BVH's `jaw` joint, its X
rotation, degrees), blinks and brows at rest, a neutral expression.

  beat2_face.py TAKE.bvh TAKE.TextGrid OUT.json
"""
import json
import re
import sys

OVR = ["sil", "PP", "FF", "TH", "DD", "kk", "CH", "SS", "nn", "RR", "aa", "E", "ih", "oh", "ou"]
CATEGORIES = ["PAU", "R", "K_G_NG", "AA", "F_V", "CH_SH_JH", "AO", "OW", "N_D_T_L", "EY", "TH_DH", "S_Z_ZH",
              "B_P_M", "HH", "W_UW"]
# ARPAbet -> (OVR viseme, thesis category), as common/face/visemes.h classes them.
PHONES = {
    "R": ("RR", "R"), "ER": ("RR", "EY"), "AXR": ("RR", "EY"),
    "K": ("kk", "K_G_NG"), "G": ("kk", "K_G_NG"), "NG": ("kk", "K_G_NG"),
    "AE": ("aa", "AA"), "AX": ("aa", "AA"), "AH": ("aa", "AA"), "AA": ("aa", "AA"), "HH": ("aa", "HH"),
    "F": ("FF", "F_V"), "V": ("FF", "F_V"),
    "CH": ("CH", "CH_SH_JH"), "SH": ("CH", "CH_SH_JH"), "JH": ("CH", "CH_SH_JH"),
    "AO": ("oh", "AO"), "AY": ("oh", "AO"), "AW": ("oh", "AO"), "OW": ("oh", "OW"), "OY": ("oh", "OW"),
    "IY": ("ih", "AO"), "IH": ("ih", "AO"), "Y": ("ih", "AO"), "IX": ("ih", "AO"),
    "N": ("nn", "N_D_T_L"), "L": ("nn", "N_D_T_L"), "NX": ("nn", "N_D_T_L"),
    "D": ("DD", "N_D_T_L"), "T": ("DD", "N_D_T_L"), "DX": ("DD", "N_D_T_L"),
    "EY": ("E", "EY"), "EH": ("E", "EY"), "EL": ("E", "EY"), "EM": ("E", "EY"), "EN": ("E", "EY"),
    "TH": ("TH", "TH_DH"), "DH": ("TH", "TH_DH"),
    "S": ("SS", "S_Z_ZH"), "Z": ("SS", "S_Z_ZH"), "ZH": ("SS", "S_Z_ZH"),
    "B": ("PP", "B_P_M"), "P": ("PP", "B_P_M"), "M": ("PP", "B_P_M"),
    "W": ("ou", "W_UW"), "UW": ("ou", "W_UW"), "UH": ("ou", "W_UW"), "UX": ("ou", "W_UW"),
}


def phones(textgrid):
    text = open(textgrid, encoding="utf-8").read()
    tier = text[text.index('name = "phones"'):]
    out = []
    for m in re.finditer(r'xmin = ([\d.]+)\s+xmax = ([\d.]+)\s+text = "([^"]*)"', tier):
        out.append((float(m.group(1)), float(m.group(2)), re.sub(r"\d", "", m.group(3)).upper()))
    return out


def jaw_track(bvh):
    lines = open(bvh).read().split("\n")
    channels, jaw_column, motion_at = 0, None, None
    current = None
    for i, line in enumerate(lines):
        words = line.split()
        if not words:
            continue
        if words[0] in ("ROOT", "JOINT"):
            current = words[1]
        elif words[0] == "CHANNELS":
            names = words[2:]
            if current == "jaw":
                jaw_column = channels + names.index("Xrotation")
            channels += len(names)
        elif words[0] == "MOTION":
            motion_at = i
            break
    frame_time = float(lines[motion_at + 2].split()[-1])
    rows = [line.split() for line in lines[motion_at + 3:] if line.strip()]
    return frame_time, [float(r[jaw_column]) for r in rows]


def main():
    bvh, textgrid, out = sys.argv[1:4]
    frame_time, jaw = jaw_track(bvh)
    tiers = phones(textgrid)
    frames = []
    for f, jaw_deg in enumerate(jaw):
        t = f * frame_time
        phone = next((p for (a, b, p) in tiers if a <= t < b), "")
        ovr, cat = PHONES.get(phone, ("sil", "PAU"))
        frames.append({
            "time_s": round(t, 6),
            "weights": [1.0 if c == cat else 0.0 for c in CATEGORIES],
            "emphasis": 0,
            "ovr": [1.0 if v == ovr else 0.0 for v in OVR],
            # SMPL-X opens the jaw with a positive X rotation; the face's 0 is closed.
            "jaw_deg": round(max(0.0, min(90.0, jaw_deg)), 4),
            "blink": 0, "blink_left": 0, "blink_right": 0, "brow": 0,
            "expression": "neutral", "expression_weight": 0,
        })
    json.dump({"frame_time_s": frame_time,
               "categories": ["VISEME_CATEGORY_" + c for c in CATEGORIES],
               "ovr_visemes": OVR,
               "frames": frames}, open(out, "w"))


if __name__ == "__main__":
    main()
