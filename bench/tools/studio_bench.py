#!/usr/bin/python3
"""The studio's cost in headless Chromium (issue 23): render_fps and the live
motion lag with the stick figure and with the skinned character, on one speech.

    bench/tools/studio_bench.py SOURCE_DIR BUILD_DIR [--runs N] [--page DIR] [--json]

Per figure ("stick": the character list's "stick figure only"; "character":
the bundled Quaternius man, skinned) and run, a fresh headless Chromium
(SwiftShader, 1500x1250 window, as the studio's browser tests use it) on one
stack:
  playback - the speech animated (BodySpeech, with visemes) and played:
             window.kinemoStudio.stats().render_fps sampled each 0.5 s for 6 s;
  live     - Chromium's fake microphone plays the same speech to
             StreamAnimate until 180 frames came: the motion lag as the page
             measures it (chunk sent -> frame received, the figure
             studio_browser_live holds to p50 < 40 ms) and, where the page
             reports it (kinemoStudio.shownLags()), chunk sent -> the first
             drawn frame that shows it; render_fps while live.
Figures alternate run by run; the table pools the runs' samples. The load
average is printed with it: on a shared machine the numbers follow it.
--page DIR serves another version of the page's files (e.g. main's
services/studio/web, checked out with `git archive`) to compare.
"""
import argparse
import json
import os
import shutil
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..', '..', 'tests', 'integration', 'studio'))

from studio_stack import SPEECH, Fail, Stack, start_stack  # noqa: E402
from studio_browser_test import render_fps, start_browser, wait_for  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.support.ui import Select  # noqa: E402

LIVE_FRAMES = 180


def percentile(values, p):
    if not values:
        return None
    s = sorted(values)
    return s[min(len(s) - 1, max(0, int(round(p / 100 * len(s) + 0.5)) - 1))]


def session(stack, url, source, figure):
    """One browser: playback render_fps, then the live stream. Returns samples."""
    tmp = tempfile.mkdtemp(prefix='studio-bench-browser-')
    driver = start_browser(tmp, os.path.join(source, 'tests/data/speech', SPEECH))
    try:
        driver.get(f'{url}?token={stack.token}')
        wait_for(driver, 'the socket', lambda s: s['connected'], 30)
        wait_for(driver, 'the bundled character', lambda s: s['skinned'], 90)
        if figure == 'stick':
            Select(driver.find_element(By.ID, 'character')).select_by_value('')
            wait_for(driver, 'the stick figure only', lambda s: not s['character'], 10)
        # Playback of the animated speech.
        Select(driver.find_element(By.ID, 'wav-sample')).select_by_visible_text(SPEECH)
        Select(driver.find_element(By.ID, 'method')).select_by_value('METHOD_BODYSPEECH')
        driver.find_element(By.ID, 'animate').click()
        wait_for(driver, 'Animate', lambda s: 'bodyspeech' in s['views'][0]['clip'] and s['playing'] and
                 (figure == 'stick' or s['character_frames'] > 0), 180)
        playback = render_fps(driver, 6)
        driver.find_element(By.ID, 'play').click()  # pause
        # Live on the same speech.
        driver.find_element(By.ID, 'live').click()
        wait_for(driver, 'live frames', lambda s: s['frames_received'] > 0, 60)
        live_fps = []
        while True:
            time.sleep(0.5)
            stats = driver.execute_script('return window.kinemoStudio.stats()')
            live_fps.append(stats['render_fps'])
            if stats['frames_received'] >= LIVE_FRAMES:
                break
        lags = driver.execute_script('return window.kinemoStudio.lags()')
        shown = driver.execute_script('const k = window.kinemoStudio; return k.shownLags ? k.shownLags() : null')
        driver.execute_script('window.kinemoStudio.stopLive()')
        driver.save_screenshot(os.path.join(stack.build, 'test-artifacts', 'studio', f'bench_{figure}.png'))
        return {'playback_fps': playback, 'live_fps': live_fps[1:], 'lags': lags, 'shown_lags': shown}
    finally:
        driver.quit()
        shutil.rmtree(tmp, ignore_errors=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('source')
    parser.add_argument('build')
    parser.add_argument('--runs', type=int, default=2, help='sessions per figure (default 2)')
    parser.add_argument('--page', default='', help="the page's files to serve (default: the build's)")
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args()
    if not 1 <= args.runs <= 20:
        parser.error('--runs: must be in [1, 20]')
    source, build = os.path.abspath(args.source), os.path.abspath(args.build)
    page = os.path.abspath(args.page) if args.page else ''
    if page and not os.path.isfile(os.path.join(page, 'index.html')):
        parser.error(f'--page: {page} has no index.html')
    os.makedirs(os.path.join(build, 'test-artifacts', 'studio'), exist_ok=True)
    tmp = tempfile.mkdtemp(prefix='studio-bench-')
    stack = Stack(build, tmp)
    figures = ['stick', 'character']
    pooled = {f: {'playback_fps': [], 'live_fps': [], 'lags': [], 'shown_lags': None} for f in figures}
    load_before = os.getloadavg()[0]
    try:
        url = start_stack(stack, source, build, with_robot=False, static_dir=page)
        for _ in range(args.runs):
            for figure in figures:
                got = session(stack, url, source, figure)
                p = pooled[figure]
                for key in ('playback_fps', 'live_fps', 'lags'):
                    p[key] += got[key]
                if got['shown_lags'] is not None:
                    p['shown_lags'] = (p['shown_lags'] or []) + got['shown_lags']
    except Fail as e:
        print(f'studio bench failed: {e}', file=sys.stderr)
        for name, _ in stack.procs:
            print(f'--- {name} log (tail) ---\n{stack.log(name)[-2000:]}', file=sys.stderr)
        return 1
    finally:
        stack.stop()
        shutil.rmtree(tmp, ignore_errors=True)
    load_after = os.getloadavg()[0]
    rows = []
    for figure in figures:
        p = pooled[figure]
        shown = p['shown_lags']
        rows.append({
            'figure': figure,
            'playback_fps_median': percentile(p['playback_fps'], 50), 'playback_fps_min': min(p['playback_fps']),
            'live_fps_median': percentile(p['live_fps'], 50),
            'live_frames': len(p['lags']),
            'lag_ms_p50': percentile(p['lags'], 50), 'lag_ms_p99': percentile(p['lags'], 99),
            'drawn_lag_ms_p50': percentile(shown, 50) if shown else None,
            'drawn_lag_ms_p99': percentile(shown, 99) if shown else None,
        })
    if args.json:
        print(json.dumps({'speech': SPEECH, 'runs': args.runs, 'page': page or 'build',
                          'load_average': [load_before, load_after], 'rows': rows}, indent=1))
        return 0
    print(f'studio bench: {SPEECH}, {args.runs} run(s) per figure, page {page or "of the build"}, '
          f'load average {load_before:.1f} -> {load_after:.1f} ({os.cpu_count()} cores)')
    print(f'{"figure":<10} {"playback fps":>13} {"(min)":>6} {"live fps":>9} {"frames":>7} '
          f'{"lag p50":>8} {"lag p99":>8} {"drawn p50":>10} {"drawn p99":>10}')
    fmt = lambda v: '-' if v is None else f'{v:.1f}'  # noqa: E731
    for r in rows:
        print(f'{r["figure"]:<10} {r["playback_fps_median"]:>13} {r["playback_fps_min"]:>6} {r["live_fps_median"]:>9} '
              f'{r["live_frames"]:>7} {fmt(r["lag_ms_p50"]):>8} {fmt(r["lag_ms_p99"]):>8} '
              f'{fmt(r["drawn_lag_ms_p50"]):>10} {fmt(r["drawn_lag_ms_p99"]):>10}')
    print('lag: chunk sent -> frame received in the page; drawn: chunk sent -> the first drawn frame showing it '
          '(ms); fps: the page\'s render_fps')
    return 0


if __name__ == '__main__':
    sys.exit(main())
