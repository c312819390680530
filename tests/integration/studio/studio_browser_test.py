#!/usr/bin/python3
"""kinemo studio in a real browser (issue 15).

    studio_browser_test.py CASE SOURCE_DIR BUILD_DIR

CASE is one of:
  page  - the page loads with no console errors; a bundled BVH plays (the hand
          joints of window.kinemoStudio.stats() move); an uploaded WAV is
          animated with GMG; a bundled recording with BodySpeech plays with
          syllables, accents, gestures and visemes on the timeline, and with
          the Gesture Controller beside it (view B); a bad socket message gets
          an error frame naming its field and the socket stays usable; an
          oversized one closes its socket with 1009.
  live  - Chromium's fake microphone plays a bundled WAV; 20 ms chunks stream
          to StreamAnimate; frames arrive and the motion lag measured in the
          page is within the live target. With the live panel's VMC receiver
          set: a malformed address (port 0) ends the stream with an error
          naming config.vmc.address; a UDP socket of the test gets the bones
          and face as VMC messages, and the page's summary counts them.
  character - the bundled Quaternius man is drawn skinned; Bandai and SMPL-X
          (BEAT2) motion, retargeted by the studio, plays on him (his hand
          bones' world positions move); an animated recording opens and
          closes his mouth with its visemes; the stick figure toggles; an
          uploaded GLB (the woman) takes his place and a bad upload gets an
          error naming `character.glb`. Prints the page's render_fps.
  face  - the face (issue 38): the VALID man, then Godette (VRM), talk live
          (Chromium's fake microphone plays a bundled WAV); the page's frame
          rate is measured and reported (kinemoStudio.measureFps); the
          drawn face targets that open the mouth open and close with the
          voice; the motion lag p50 stays within the live target.
          Screenshots of view A with the mouth open and with the lips
          closed: face_<character>_open.png, face_<character>_closed.png.
  vleo  - a session with an angry Pleo (pleo_sim behind the all-in-one's robot
          bridge); "Throw kisses" turns Pleo neutral on the page.
  cube  - the cube sets the mood (issue 24): the bundled cube video (the
          studio renders tests/data/cube/tone_scenario.json: idle, kisses from
          ~2.3 s, shouting from ~7.5 s) is attached to a new session through
          the page and Chromium's fake microphone plays a bundled WAV; the
          page shows at least two top faces and two tones of the character as
          they come, and Pleo ends in the emotion the session's model
          predicts (angry, as cube_tones_test has it), as pleo_sim shows it.
          The video ends and the page says so; a WAV as the cube video is
          refused naming attach_cube.upload; the rendered video uploaded as
          the user's own (with its camera) drives the tone of a streamed
          recording; Detach removes the upload. The AR view (the bundled
          video with the character drawn beside the cube, drawn by the studio
          after the attach) loads and plays in the cube panel's <video>; its
          route refuses requests without the token (401) and names that are
          not AR videos (400). Writes cube_ar.png and the video, cube_ar.webm.

Starts its own stack on loopback with ephemeral ports (--port 0 --port-file),
waits on health (gRPC health via kinemo-health, GET /healthz for the studio),
stops only the processes it started. Each case writes a screenshot to
BUILD_DIR/test-artifacts/studio/<case>.png. Exit 77 (skip) only where
Chromium cannot start.
"""
import os
import re
import shutil
import socket
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request

from studio_stack import SPEECH, Fail, Stack, check, start_stack

from selenium import webdriver
from selenium.common.exceptions import WebDriverException
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select

SKIP = 77
BVH = 'dataset-1_guide_normal_001.bvh'
# The live-gesture targets (issue 14, docs/benchmarks.md "Live speech -> motion"): motion
# lag p50 <= 40 ms, p99 <= 80 ms. Measured here in the page (chunk sent on the
# socket -> frame received from it), so the browser's main thread is included.
# p50 is held to the target. p99 (the 2nd-worst of ~180 frames) follows the
# machine's stalls: on an idle machine it is ~45 ms, at a load of 15 on 2
# cores ~110 ms; it is held to 250 ms, which still fails when frames are
# batched, held back by rendering, or wait for later chunks (>= 3 chunks).
LIVE_LAG_P50_MS = 40
LIVE_LAG_P99_MS = 250


def start_browser(tmp, fake_audio=None):
    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which('chromium') or '/usr/bin/chromium'
    for flag in ['--headless=new', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
                 '--disable-background-networking', '--disable-component-update', '--disable-sync',
                 '--disable-dev-shm-usage', '--use-gl=angle', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
                 '--autoplay-policy=no-user-gesture-required', '--window-size=1500,1250',
                 f'--user-data-dir={os.path.join(tmp, "chromium-profile")}']:
        options.add_argument(flag)
    if fake_audio:
        options.add_argument('--use-fake-device-for-media-stream')
        options.add_argument('--use-fake-ui-for-media-stream')
        options.add_argument(f'--use-file-for-fake-audio-capture={fake_audio}')
    options.set_capability('goog:loggingPrefs', {'browser': 'ALL'})
    driver_path = shutil.which('chromedriver') or '/usr/bin/chromedriver'
    service = Service(driver_path, log_output=os.path.join(tmp, 'chromedriver.log')) \
        if 'log_output' in Service.__init__.__code__.co_varnames \
        else Service(driver_path, log_path=os.path.join(tmp, 'chromedriver.log'))
    return webdriver.Chrome(service=service, options=options)


def wait_for(driver, what, predicate, timeout_s, poll_s=0.1):
    """Polls window.kinemoStudio.stats() until predicate(stats) holds."""
    deadline = time.monotonic() + timeout_s
    stats = None
    while time.monotonic() < deadline:
        stats = driver.execute_script('return window.kinemoStudio ? window.kinemoStudio.stats() : null')
        if stats is not None and predicate(stats):
            return stats
        time.sleep(poll_s)
    raise Fail(f'timed out after {timeout_s} s waiting for {what}; last stats: {stats}')


def console_errors(driver):
    errors = []
    for entry in driver.get_log('browser'):
        if entry.get('level') == 'SEVERE':
            errors.append(entry.get('message', ''))
    return errors


def hands(stats):
    return [(h['x'], h['y'], h['z']) for h in stats['hand_positions']]


def moved(a, b, metres=0.01):
    return any(max(abs(p - q) for p, q in zip(u, v)) > metres for u, v in zip(a, b))


def case_page(driver, url, source):
    driver.get(url)
    wait_for(driver, 'the socket', lambda s: s['connected'], 20)
    # The page's first character is drawn before a clip comes (the clip is
    # retargeted onto it).
    wait_for(driver, 'the first character', lambda s: s['skinned'], 60)
    # A bundled BVH plays: the hands move over time.
    Select(driver.find_element(By.ID, 'bvh-sample')).select_by_visible_text(BVH)
    driver.find_element(By.ID, 'play-bvh').click()
    try:
        first = wait_for(driver, 'the BVH to play', lambda s: s['playing'] and len(s['hand_positions']) == 2, 30)
    except Fail as e:
        texts = {i: driver.find_element(By.ID, i).text for i in ('bvh-status', 'character-status', 'connection')}
        raise Fail(f'{e}; page: {texts}; console: {console_errors(driver)}')
    check([h['joint'] for h in first['hand_positions']] == ['Hand_L', 'Hand_R'],
          f'hand joints: {first["hand_positions"]}')
    later = wait_for(driver, 'the hands to move', lambda s: s['time_s'] > first['time_s'] + 0.5 and
                     moved(hands(first), hands(s)), 10)
    print(f'bvh: hands at {first["time_s"]:.2f} s {hands(first)} -> {later["time_s"]:.2f} s {hands(later)}')
    # Upload a recording of one's own (GMG).
    upload = os.path.join(source, 'tests/data/speech/sense_and_sensibility_01_austen_64kb-0880.wav')
    driver.find_element(By.ID, 'wav-file').send_keys(upload)
    Select(driver.find_element(By.ID, 'method')).select_by_value('METHOD_GMG')
    driver.find_element(By.ID, 'animate').click()
    gmg = wait_for(driver, 'Animate of an uploaded WAV', lambda s: 'gmg' in s['views'][0]['clip'] and s['playing'], 120)
    check(2.5 < gmg['views'][0]['duration_s'] < 3.5, f'uploaded 3 s WAV gave {gmg["views"][0]}')
    print(f'upload: {gmg["views"][0]}')
    driver.execute_script("document.getElementById('wav-file').value = ''")
    # Animate a bundled recording (BodySpeech) and play it with its timeline.
    Select(driver.find_element(By.ID, 'wav-sample')).select_by_visible_text(SPEECH)
    Select(driver.find_element(By.ID, 'method')).select_by_value('METHOD_BODYSPEECH')
    driver.find_element(By.ID, 'animate').click()
    done = wait_for(driver, 'Animate', lambda s: s['duration_s'] > 6 and s['playing'] and s['time_s'] > 1.0, 120)
    check(moved(hands(later), hands(done)), 'the animated hands are where the BVH left them')
    caption = driver.find_element(By.ID, 'timeline-caption').text
    status = driver.find_element(By.ID, 'animate-status').text
    print(f'animate: {status} | timeline: {caption}')
    check('animate failed' not in status, status)
    counts = [int(w) for w in caption.replace(',', ' ').split() if w.isdigit()]
    check(len(counts) >= 4 and counts[0] > 5 and counts[1] > 0 and counts[2] > 0 and counts[3] > 0,
          f'timeline lacks syllables, accents, gestures or visemes: {caption}')
    # The same recording with the Gesture Controller in view B, side by side.
    Select(driver.find_element(By.ID, 'method')).select_by_value('METHOD_GESTURE_CONTROLLER')
    Select(driver.find_element(By.ID, 'slot')).select_by_value('1')
    driver.find_element(By.ID, 'animate').click()
    both = wait_for(driver, 'Animate into view B', lambda s: 'gesture_controller' in s['views'][1]['clip'] and
                    s['playing'] and s['time_s'] > 0.5, 120)
    check('bodyspeech' in both['views'][0]['clip'], f'view A lost its clip: {both["views"]}')
    print(f'side by side: {both["views"]}')
    # Let it play to a busy moment for the screenshot.
    wait_for(driver, 'playback', lambda s: s['time_s'] > 3.0, 10)
    driver.execute_script("document.getElementById('play').click()")  # pause
    paused = wait_for(driver, 'pause', lambda s: not s['playing'], 5)
    check(moved(hands(done), hands(paused)), 'the animated hands did not move between 1 s and 3 s')
    # A bad message gets an error frame naming the field; the socket stays usable.
    answer = driver.execute_async_script('''
        const done = arguments[arguments.length - 1];
        const ws = new WebSocket(`ws://${location.host}/ws`);
        const got = [];
        ws.onmessage = (e) => {
          const m = JSON.parse(e.data);
          got.push(m);
          if (m.hello) ws.send(JSON.stringify({id: 7, act: {sessionId: "x", intensity: "loud"}}));
          else if (m.id === 7) ws.send(JSON.stringify({id: 8, listSessions: {}}));
          else if (m.id === 8) { ws.close(); done(got); }
        };
        setTimeout(() => done(got), 10000);''')
    check(len(answer) == 3 and 'error' in answer[1] and answer[1]['error']['message'].startswith('act.intensity'),
          f'bad message answer: {answer}')
    check('listSessions' in answer[2], f'socket not usable after an error: {answer}')
    print(f'bad message -> {answer[1]["error"]}')
    # A message over max_upload_bytes closes that socket with 1009 (message too big).
    closed = driver.execute_async_script('''
        const done = arguments[arguments.length - 1];
        const ws = new WebSocket(`ws://${location.host}/ws`);
        ws.onmessage = (e) => {
          if (JSON.parse(e.data).hello) {
            ws.send(JSON.stringify({id: 1, animate: {audio: {data: btoa('x'.repeat(1100000))}}}));
          }
        };
        ws.onclose = (e) => done(e.code);
        setTimeout(() => done(null), 10000);''')
    check(closed == 1009, f'an oversized message closed the socket with {closed}, not 1009')
    wait_for(driver, 'the page\'s own socket to stay open', lambda s: s['connected'], 2)
    errors = console_errors(driver)
    check(not errors, f'console errors: {errors}')


class VmcReceiver:
    """A UDP socket on an ephemeral loopback port that keeps the datagrams
    the coordinator sends it (OSC bundles of VMC messages)."""

    def __init__(self):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(('127.0.0.1', 0))
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.datagrams = []
        self.running = True
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while self.running:
            try:
                self.datagrams.append(self.sock.recv(65536))
            except socket.timeout:
                pass

    def close(self):
        self.running = False
        self.thread.join()
        self.sock.close()


def open_vmc_panel(driver, address):
    driver.execute_script("document.getElementById('vmc').open = true")
    field = driver.find_element(By.ID, 'vmc-address')
    field.clear()
    field.send_keys(address)


def case_live(driver, url, source):
    driver.get(url)
    wait_for(driver, 'the socket', lambda s: s['connected'], 20)
    # The live panel's VMC receiver: a malformed address ends the stream at
    # once with the coordinator's error naming the field; a real one gets
    # the live bones and face while the page shows the stream.
    open_vmc_panel(driver, '127.0.0.1:0')
    driver.find_element(By.ID, 'live').click()
    refused = wait_for_status(driver, 'live-status', lambda t: 'failed' in t, 30)
    check('config.vmc.address' in refused, f'a VMC address with port 0: {refused!r}')
    check(driver.find_element(By.ID, 'live').text == 'Start microphone', 'the refused stream still shows as live')
    print(f'live: VMC port 0 refused: {refused!r}')
    receiver = VmcReceiver()
    try:
        case_live_vmc(driver, receiver)
    finally:
        receiver.close()


def case_live_vmc(driver, receiver):
    open_vmc_panel(driver, f'127.0.0.1:{receiver.port}')
    driver.find_element(By.ID, 'live').click()
    wait_for(driver, 'the bundled character, drawn', lambda s: s['skinned'] and len(s['character_hands']) == 2, 60)
    first = wait_for(driver, 'live frames', lambda s: s['frames_received'] > 0, 30)
    fps = measure_fps(driver, 4)
    print(f'live: {stats_line(fps)} (drawing {first["character"]}, 1500x1250 window, SwiftShader; '
          f'load average {os.getloadavg()[0]:.1f})')
    stats = wait_for(driver, '6 s of live frames', lambda s: s['frames_received'] >= 180, 40)
    check(moved(hands(first), hands(stats), 0.005), 'the live hands did not move')
    check(stats['character_frames_received'] > 0.9 * stats['frames_received'],
          f'live frames on the character: {stats["character_frames_received"]} of {stats["frames_received"]}')
    check(moved(character_hands(first), character_hands(stats), 0.005), 'the character\'s live hands did not move')
    print(f'live: {stats["character_frames_received"]} frames retargeted onto {stats["character"]}')
    lags = driver.execute_script('return window.kinemoStudio.lags()')
    lags.sort()
    p50 = lags[len(lags) // 2]
    shown = driver.find_element(By.ID, 'live-lag-p99').text
    drawn = sorted(driver.execute_script('return window.kinemoStudio.shownLags()'))
    print(f'live: {stats["frames_received"]} frames, motion lag p50 {p50:.1f} ms, '
          f'p99 {stats["motion_lag_ms_p99"]:.1f} ms, max {lags[-1]:.1f} ms (page shows p99 {shown}); '
          f'until drawn p50 {drawn[len(drawn) // 2] if drawn else float("nan"):.1f} ms over {len(drawn)} renders; '
          f'load average {os.getloadavg()[0]:.1f}')
    check(shown.endswith('ms'), f'the page does not show the lag: {shown!r}')
    check(p50 < LIVE_LAG_P50_MS, f'motion lag p50 {p50:.1f} ms over {LIVE_LAG_P50_MS} ms')
    check(stats['motion_lag_ms_p99'] < LIVE_LAG_P99_MS,
          f'motion lag p99 {stats["motion_lag_ms_p99"]:.1f} ms over {LIVE_LAG_P99_MS} ms')
    # The VMC app's side: bone and face messages (Unity names), and the
    # stream's summary on the page once the microphone stops.
    got = list(receiver.datagrams)
    bones = sum(1 for d in got if b'/VMC/Ext/Bone/Pos' in d and b'Hips' in d)
    faces = sum(1 for d in got if b'/VMC/Ext/Blend/Val' in d and b'Blink_L' in d)
    check(bones >= stats['frames_received'] // 2 and faces > 0,
          f'VMC receiver: {len(got)} datagrams, {bones} with the Hips bone, {faces} with the face, '
          f'for {stats["frames_received"]} frames')
    driver.find_element(By.ID, 'live').click()
    summary = wait_for_status(driver, 'live-status', lambda t: 'to VMC' in t, 30)
    m = re.search(r'to VMC 127\.0\.0\.1:(\d+): (\d+) frames in (\d+) datagrams', summary)
    check(m is not None and int(m.group(1)) == receiver.port and int(m.group(2)) > 0 and
          int(m.group(3)) <= len(receiver.datagrams), f'the page after stopping: {summary!r}')
    print(f'live: VMC receiver got {len(receiver.datagrams)} datagrams ({bones} with bones, {faces} with the face '
          f'while checked); page: {summary!r}')
    errors = console_errors(driver)
    check(not errors, f'console errors: {errors}')


def measure_fps(driver, seconds):
    """The page's frame rate over `seconds` (kinemoStudio.measureFps):
    requestAnimationFrame timing on the page's thread and view A's drawn frames."""
    return driver.execute_async_script('const done = arguments[arguments.length - 1];'
                                       'window.kinemoStudio.measureFps(arguments[0]).then(done);', seconds)


def stats_line(fps):
    d, r = fps['drawn'], fps['raf']
    return (f'drawn {d["fps"]:.1f} fps (interval p50 {d["interval_ms_p50"]:.0f} ms, p95 {d["interval_ms_p95"]:.0f} ms, '
            f'{d["frames"]} frames in {fps["seconds"]} s), page rAF {r["fps"]:.1f} fps')


def character_hands(stats):
    return [(h['x'], h['y'], h['z']) for h in stats['character_hands']]


def seek(driver, t):
    """Moves the playhead to t; returns the stats once the renderer has drawn
    the pose at t (character_hands and face are what it drew)."""
    driver.execute_script("const s = document.getElementById('scrub'); s.value = String(arguments[0]);"
                          "s.dispatchEvent(new Event('input'));", t)
    return wait_for(driver, f'the pose at {t} s drawn', lambda s: abs(s['pose_time_s'] - t) < 0.01 and
                    abs(s['drawn_pose_time_s'] - t) < 0.01, 10)


def play_on_character(driver, bvh):
    """Plays a bundled BVH on the character; its hand bones are elsewhere at
    two times of the clip (paused and seeked, so a slow machine cannot miss
    the motion)."""
    Select(driver.find_element(By.ID, 'bvh-sample')).select_by_visible_text(bvh)
    driver.find_element(By.ID, 'play-bvh').click()
    loaded = wait_for(driver, f'{bvh} on the character', lambda s: s['views'][0]['clip'] == bvh and
                      s['character_frames'] > 0 and len(s['character_hands']) == 2, 60)
    if loaded['playing']:
        driver.find_element(By.ID, 'play').click()
        wait_for(driver, 'pause', lambda s: not s['playing'], 5)
    duration = loaded['duration_s']
    a = seek(driver, round(0.1 * duration, 2))
    b = seek(driver, round(0.6 * duration, 2))
    check(moved(character_hands(a), character_hands(b)),
          f'the character\'s hands did not move between {a["time_s"]:.2f} s and {b["time_s"]:.2f} s of {bvh}')
    print(f'{bvh} on {b["character"]}: {b["character_frames"]} frames; hands at {a["time_s"]:.2f} s '
          f'{character_hands(a)} -> {b["time_s"]:.2f} s {character_hands(b)}')
    driver.find_element(By.ID, 'play').click()
    return wait_for(driver, f'{bvh} to play', lambda s: s['playing'], 5)


def render_fps(driver, seconds):
    """The page's own render_fps, sampled each 0.5 s while it plays."""
    samples = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        time.sleep(0.5)
        stats = driver.execute_script('return window.kinemoStudio.stats()')
        if stats['playing']:
            samples.append(stats['render_fps'])
    samples.sort()
    return samples


def case_character(driver, url, source):
    driver.get(url)
    wait_for(driver, 'the socket', lambda s: s['connected'], 20)
    man = wait_for(driver, 'the bundled man, skinned and drawn', lambda s: s['character'] == 'quaternius_man_casual.glb'
                   and s['skinned'] and len(s['character_hands']) == 2, 60)
    check(man['character_hands'] and not man['hand_positions'], f'hands before any motion: {man}')
    play_on_character(driver, BVH)                  # Bandai
    smplx = play_on_character(driver, '2_scott_0_1_1.bvh')   # SMPL-X (BEAT2)
    check(smplx['views'][0]['clip'] == '2_scott_0_1_1.bvh', f'view A: {smplx["views"]}')
    fps = render_fps(driver, 6)
    check(fps and fps[-1] > 0, f'the page rendered nothing while playing: {fps}')
    print(f'render_fps of one skinned character (SMPL-X motion, 1500x1250 window, SwiftShader): '
          f'median {fps[len(fps) // 2]}, min {fps[0]}, max {fps[-1]} over {len(fps)} samples; '
          f'load average {os.getloadavg()[0]:.1f}')
    # An animated recording: the mouth follows its visemes.
    Select(driver.find_element(By.ID, 'wav-sample')).select_by_visible_text(SPEECH)
    Select(driver.find_element(By.ID, 'method')).select_by_value('METHOD_BODYSPEECH')
    driver.find_element(By.ID, 'animate').click()
    animated = wait_for(driver, 'Animate on the character', lambda s: 'bodyspeech' in s['views'][0]['clip'] and
                        s['playing'] and 150 < s['character_frames'] < 1000, 180)
    length = animated['views'][0]['duration_s']
    driver.find_element(By.ID, 'play').click()  # pause
    wait_for(driver, 'pause', lambda s: not s['playing'], 5)
    a = seek(driver, round(0.3 * length, 2))
    b = seek(driver, round(0.7 * length, 2))
    check(moved(character_hands(a), character_hands(b)), f'the man\'s hands did not move with {SPEECH}')
    driver.save_screenshot(os.path.join(os.path.dirname(SHOT_DIR[0]), 'character_man.png'))
    # Godette (VRM 0.x, three-vrm): the same recording on her, her credit
    # (CC BY 3.0) under the menu.
    Select(driver.find_element(By.ID, 'character')).select_by_value('godette.vrm')
    godette = wait_for(driver, 'Godette, drawn with the recording', lambda s: s['character'] == 'godette.vrm' and
                       s['skinned'] and len(s['character_hands']) == 2 and 150 < s['character_frames'] < 1000, 60)
    credit = driver.find_element(By.ID, 'character-credit').text
    check('Godette' in credit and 'CC BY 3.0' in credit, f'Godette\'s credit: {credit!r}')
    a = seek(driver, round(0.3 * length, 2))
    b = seek(driver, round(0.7 * length, 2))
    check(moved(character_hands(a), character_hands(b)), f'Godette\'s hands did not move with {SPEECH}')
    print(f'godette.vrm: {godette["character_frames"]} frames; hands {character_hands(a)} -> {character_hands(b)}; '
          f'credit {credit!r}')
    driver.save_screenshot(os.path.join(os.path.dirname(SHOT_DIR[0]), 'character_godette.png'))
    # The recording on her as a VRM Animation (the studio writes it: export_motion).
    download_on_character(driver, '.vrma', os.path.splitext(SPEECH)[0] + '.vrma')
    Select(driver.find_element(By.ID, 'character')).select_by_value('quaternius_man_casual.glb')
    wait_for(driver, 'the man again', lambda s: s['character'] == 'quaternius_man_casual.glb' and s['skinned'] and
             s['character_frames'] > 150, 60)
    download_on_character(driver, '.glb', os.path.splitext(SPEECH)[0] + '.glb')
    # The stick figure, as a toggle.
    driver.find_element(By.ID, 'stick').click()
    wait_for(driver, 'the stick figure', lambda s: not s['skinned'], 5)
    driver.find_element(By.ID, 'stick').click()
    wait_for(driver, 'the character again', lambda s: s['skinned'], 5)
    # A bad upload is refused, naming the field; the man stays.
    driver.find_element(By.ID, 'character-file').send_keys(os.path.join(source, 'tests/data/speech', SPEECH))
    status = wait_for_status(driver, 'character-status', lambda t: t.startswith('character.glb: '), 20)
    print(f'bad upload: {status}')
    check(driver.execute_script('return window.kinemoStudio.stats().character') == 'quaternius_man_casual.glb',
          'a bad upload replaced the character')
    # The user's own GLB: the same motion on it.
    driver.execute_script("document.getElementById('character-file').value = ''")
    driver.find_element(By.ID, 'character-file').send_keys(
        os.path.join(source, 'tests/data/characters/quaternius_woman_casual.glb'))
    woman = wait_for(driver, 'the uploaded woman', lambda s: s['character'] == 'quaternius_woman_casual.glb' and
                     s['skinned'] and s['character_frames'] > 150, 60)
    print(f'upload: {driver.find_element(By.ID, "character-status").text}')
    # From early in the recording (it was paused at 70 %: under load the
    # 2 s left could play out before a sample saw the hands move).
    if woman['playing']:
        driver.execute_script("document.getElementById('play').click()")
        wait_for(driver, 'pause', lambda s: not s['playing'], 5)
    woman = seek(driver, round(0.1 * length, 2))
    driver.execute_script("document.getElementById('play').click()")
    later = wait_for(driver, 'the woman\'s hands to move', lambda s: s['playing'] and
                     moved(character_hands(woman), character_hands(s)), 20)
    check(later['character_frames'] == woman['character_frames'], 'the motion changed with the character')
    # An uploaded VRM: drawn with three-vrm, credited from its own meta.
    driver.execute_script("document.getElementById('character-file').value = ''")
    driver.find_element(By.ID, 'character-file').send_keys(os.path.join(source, 'tests/data/characters/godette.vrm'))
    wait_for(driver, 'the uploaded VRM', lambda s: s['character'] == 'godette.vrm' and s['skinned'] and
             s['character_frames'] > 150, 60)
    credit = wait_for_status(driver, 'character-credit', lambda t: t != '', 10)
    print(f'uploaded VRM credited from its meta: {credit!r}')
    check('Lyuma' in credit or 'SirRichard94' in credit, f'the uploaded VRM\'s credit: {credit!r}')
    errors = console_errors(driver)
    check(not errors, f'console errors: {errors}')


def download_on_character(driver, extension, file_name):
    """'Download on the character' after an Animate: the button names the
    format for the chosen character, and the studio writes the file."""
    label = driver.find_element(By.ID, 'download-character')
    check(label.is_displayed() and extension in label.text, f'the download button: {label.text!r}')
    driver.execute_script("document.getElementById('download-character').click()")
    status = wait_for_status(driver, 'animate-status', lambda t: t.startswith(file_name + ':') or
                             t.startswith('download on the character:'), 60)
    print(f'download on the character ({label.text}): {status}')
    check(status.startswith(file_name + ':') and ' MB on ' in status, f'the download: {status!r}')


def wait_for_status(driver, element_id, predicate, timeout_s):
    deadline = time.monotonic() + timeout_s
    got = ''
    while time.monotonic() < deadline:
        got = driver.find_element(By.ID, element_id).text
        if predicate(got):
            return got
        time.sleep(0.1)
    raise Fail(f'#{element_id} shows {got!r} after {timeout_s} s')


def case_vleo(driver, url, source):
    driver.get(url)
    wait_for(driver, 'the socket', lambda s: s['connected'], 20)
    Select(driver.find_element(By.ID, 'initial-emotion')).select_by_value('EMOTION_ANGRY')
    driver.find_element(By.ID, 'open-session').click()
    wait_for(driver, 'an angry Pleo', lambda s: s['session_id'] and s['pleo_emotion'] == 'angry', 20)
    wait_for_text(driver, 'robot-status', 'connected', 20)
    driver.find_element(By.CSS_SELECTOR, 'button.act[data-action="ACTION_KISSES"]').click()
    stats = wait_for(driver, 'Pleo to turn neutral', lambda s: s['pleo_emotion'] == 'neutral', 30)
    wait_for_text(driver, 'robot-emotion', 'neutral', 20)
    print(f'vleo: session {stats["session_id"]}: angry -> kisses -> {stats["pleo_emotion"]}; robot shows '
          f'{driver.find_element(By.ID, "robot-emotion").text}')
    driver.execute_script("document.getElementById('vleo-title').scrollIntoView()")
    errors = console_errors(driver)
    check(not errors, f'console errors: {errors}')


# Face targets whose channel opens the mouth (the jaw, open and rounded
# vowels) or closes the lips (PP: m, b, p), as the rig's face mapping names
# the channels (studio.proto FaceTarget.channel).
OPENING = re.compile(r'jaw|\b(aa|oh|ou|E|ih)\b|mouth_?open', re.IGNORECASE)
CLOSING = re.compile(r'\bPP\b')


def mouth(face, pattern=OPENING):
    """The largest drawn weight of the face targets whose channel matches."""
    if not face:
        return 0.0
    return max([w for name, w in face['weights'].items() if pattern.search(face['channels'].get(name, ''))] or [0.0])


def swings(values, step):
    """How many times `values` turns after moving by >= step from its last
    turning point (a mouth opening then closing by 0.3 counts two)."""
    count, anchor, direction = 0, values[0] if values else 0.0, 0
    for v in values[1:]:
        if direction >= 0 and v <= anchor - step:
            count, direction, anchor = count + 1, -1, v
        elif direction <= 0 and v >= anchor + step:
            count, direction, anchor = count + 1, 1, v
        elif (direction > 0 and v > anchor) or (direction < 0 and v < anchor):
            anchor = v
    return count


CLOSE_UP_S = 5


def talk_live(driver, name, seconds):
    """`name` talks live (the fake microphone): the drawn mouth sampled every
    50 ms for `seconds`; returns (samples, fps, best_open, best_closed). Then
    CLOSE_UP_S with the face close-up: screenshots of view A with the mouth
    most open and with the lips closed on m/b/p go to face_<name>_open.png
    and face_<name>_closed.png."""
    Select(driver.find_element(By.ID, 'character')).select_by_value(name)
    drawn = wait_for(driver, f'{name} drawn with its face', lambda s: s['character'] == name and s['skinned'] and
                     s['face'] and s['face']['bound'] > 0, 90)
    print(f'face: {name}: {drawn["face"]["bound"]} face targets bound: {sorted(drawn["face"]["channels"].values())}')
    driver.find_element(By.ID, 'live').click()
    wait_for(driver, 'live frames', lambda s: s['frames_received'] > 30 and s['character_frames_received'] > 30, 40)
    fps = measure_fps(driver, 4)
    print(f'face: {name} live: {stats_line(fps)}; load average {os.getloadavg()[0]:.1f}')
    # The mouth on the whole figure (what the checks judge, at the frame rate
    # above).
    samples = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        face = driver.execute_script('return window.kinemoStudio.stats().face')
        samples.append((mouth(face), mouth(face, CLOSING)))
        time.sleep(0.05)
    # Then the face close-up, for the screenshots: the camera goes to 2.6
    # head sizes in front of the drawn face and follows it while the body
    # moves.
    driver.execute_script("const c = document.getElementById('close-up'); if (!c.checked) c.click();")
    near = wait_for(driver, f'the close-up on {name}\'s face', lambda s: s['face_distance_m'] is not None and
                    s['face_size_m'] and s['face_distance_m'] < 3 * s['face_size_m'], 20)
    print(f'face: {name}: close-up camera {near["face_distance_m"]} m from the face (head {near["face_size_m"]} m)')
    best_open, best_closed, distances = 0.0, 0.0, []
    view = driver.find_element(By.ID, 'view-a')
    shots = os.path.dirname(SHOT_DIR[0])
    deadline = time.monotonic() + CLOSE_UP_S
    while time.monotonic() < deadline:
        stats = driver.execute_script('return window.kinemoStudio.stats()')
        distances.append(stats['face_distance_m'])
        opening, closing = mouth(stats['face']), mouth(stats['face'], CLOSING)
        if opening > best_open + 0.05:
            view.screenshot(os.path.join(shots, f'face_{name}_open.png'))
            best_open = opening
        if closing > best_closed + 0.05 and opening < 0.1:
            view.screenshot(os.path.join(shots, f'face_{name}_closed.png'))
            best_closed = closing
        time.sleep(0.05)
    driver.find_element(By.ID, 'live').click()
    wait_for(driver, 'the microphone to stop', lambda s: not s['playing'], 10)
    far = max(d for d in distances if d is not None)
    print(f'face: {name}: the close-up camera stayed within {far:.2f} m of the moving face')
    check(far < 3 * near['face_size_m'], f'the close-up lost {name}\'s face while the body moved: {distances}')
    driver.execute_script("const c = document.getElementById('close-up'); if (c.checked) c.click();")
    return samples, fps, best_open, best_closed


def case_face(driver, url, source):
    driver.get(url)
    wait_for(driver, 'the socket', lambda s: s['connected'], 20)
    for name in ('valid_white_m_1_casual.glb', 'godette.vrm'):
        samples, fps, best_open, best_closed = talk_live(driver, name, 6)
        opening = [o for o, _ in samples]
        # Opening and closing with the voice: wide open on vowels, shut in
        # pauses, and many visible swings over 6 s of speech (a swing: the
        # opening moves by >= 0.3 of full open from its last turning point;
        # between syllables a rig's vowel weight need not reach 0).
        changes = swings(opening, 0.3)
        print(f'face: {name}: mouth opening over {len(opening)} samples: max {max(opening):.2f}, '
              f'min {min(opening):.2f}, {changes} swings of >= 0.3; lips closed (PP) at most {best_closed:.2f}')
        check(max(opening) > 0.4 and min(opening) < 0.1 and changes >= 6,
              f'{name}\'s mouth does not open and close with the voice: {opening}')
        lags = sorted(driver.execute_script('return window.kinemoStudio.lags()'))
        p50 = lags[len(lags) // 2]
        print(f'face: {name}: motion lag p50 {p50:.1f} ms over {len(lags)} frames')
        check(p50 < LIVE_LAG_P50_MS, f'motion lag p50 {p50:.1f} ms over {LIVE_LAG_P50_MS} ms with the face')
    errors = console_errors(driver)
    check(not errors, f'console errors: {errors}')


def wait_cube(driver, what, predicate, timeout_s, poll_s=0.1):
    """Polls window.kinemoStudio.cube() (what the cube panel shows)."""
    deadline = time.monotonic() + timeout_s
    got = None
    while time.monotonic() < deadline:
        got = driver.execute_script('return window.kinemoStudio.cube()')
        if predicate(got):
            return got
        time.sleep(poll_s)
    raise Fail(f'timed out after {timeout_s} s waiting for {what}; the cube panel shows {got}')


def click_taken(driver, element_id, what, taken, timeout_s=10):
    """Clicks a button and waits until the cube panel shows the page took the
    click (taken(cube) holds). WebDriver aims a click at where the button was
    laid out; while the page still lays out (characters and panels loading on
    a loaded machine) it can land beside the button and nothing happens (CI
    once: the panel's status stayed empty for 180 s after Attach). Then the
    button is scrolled into view and clicked once more, said in the log."""
    button = driver.find_element(By.ID, element_id)
    button.click()
    try:
        return wait_cube(driver, what, taken, timeout_s)
    except Fail:
        print(f'note: the page did not take the click on #{element_id} in {timeout_s} s; clicking it again')
    driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", button)
    button.click()
    return wait_cube(driver, what, taken, timeout_s)


def session_emotion(driver, session_id):
    """The session's state as the coordinator has it (GetSession on a socket
    of the test's own): the emotion its model holds and what the robot shows."""
    got = driver.execute_async_script('''
        const done = arguments[arguments.length - 1];
        const ws = new WebSocket(`ws://${location.host}/ws`);
        ws.onmessage = (e) => {
          const m = JSON.parse(e.data);
          if (m.hello) ws.send(JSON.stringify({id: 1, getSession: {sessionId: arguments[0]}}));
          else { ws.close(); done(m); }
        };
        setTimeout(() => done(null), 10000);''', session_id)
    check(got and 'getSession' in got, f'get_session: {got}')
    return got['getSession'].get('emotion', ''), got['getSession'].get('robotEmotion', '')


def case_cube(driver, url, source):
    driver.set_window_size(1500, 2300)  # the views and the Vleo-Pleo panel in one screenshot
    driver.get(url)
    wait_for(driver, 'the socket', lambda s: s['connected'], 20)
    wait_cube(driver, 'the bundled scenarios', lambda c: driver.find_element(By.ID, 'cube-scenario').get_attribute(
        'value') == 'tone_scenario', 10)
    Select(driver.find_element(By.ID, 'initial-emotion')).select_by_value('EMOTION_NEUTRAL')
    # Attach the bundled video (the studio draws it on its first use), then talk.
    click_taken(driver, 'cube-attach', 'the page to take Attach', lambda c: c['status'] != '')
    attached = wait_cube(driver, 'the bundled cube attached', lambda c: c['attached'] and 'attached to' in c['status'],
                         180)
    print(f'cube: {attached["status"]}; face {attached["face"]}, intensity {attached["intensity"]} at attach')
    # The first tracked frame's face is the attach's state: shown at once,
    # before any turn (the scenario first turns at ~1.7 s; an idle face up).
    check(attached['face'] in ('pos_z', 'neg_z') and attached['intensity'] == '0.00',
          f'the face at attach: {attached}')
    check(attached['faces_shown'][:1] == [attached['face']], f'faces shown from the attach: {attached}')
    driver.find_element(By.ID, 'live').click()
    # Idle, then kisses, then shouting: the faces and the character's tones change on the page.
    seen = wait_cube(driver, 'two faces and three tones', lambda c: len(set(c['faces_shown'])) >= 2 and
                     c['tones_shown'][-1:] == ['angry'], 60)
    print(f'cube: faces shown {seen["faces_shown"]}, tones shown {seen["tones_shown"]}, now {seen["tone"]} '
          f'{seen["weight"]:.2f} at cube intensity {seen["intensity"]}, Pleo {seen["pleo_emotion"]}')
    check(len(set(seen['tones_shown'])) >= 2 and seen['tones_shown'][0] == 'neutral',
          f'tones shown: {seen["tones_shown"]}')
    live = wait_for(driver, 'live frames', lambda s: s['frames_received'] > 150, 20)
    check(live['character_frames_received'] > 0, 'no live frames on the character')
    # Pleo: angry by ~10 s of the video (kisses make it happy, shouting from
    # 7.5 s brings it to angry), on the page, in the model and on pleo_sim.
    angry = wait_cube(driver, 'an angry Pleo on the page', lambda c: c['pleo_emotion'] == 'angry' and
                      c['robot_emotion'] == 'angry', 40)
    # The coordinator's view (GetSession): the robot's state is polled by the
    # bridge, so it may trail the page's event by a poll or a retry under load.
    deadline = time.monotonic() + 15
    while True:
        model, robot = session_emotion(driver, angry['session_id'])
        if (model == 'EMOTION_ANGRY' and robot == 'EMOTION_ANGRY') or time.monotonic() > deadline:
            break
        time.sleep(0.2)
    print(f'cube: Pleo on the page {angry["pleo_emotion"]} (robot shows {angry["robot_emotion"]}); the session\'s '
          f'model {model}, the robot {robot}')
    check(model == 'EMOTION_ANGRY' and robot == 'EMOTION_ANGRY', f'the model says {model}, the robot shows {robot}')
    driver.execute_script("document.getElementById('cube-attach-panel').scrollIntoView({block: 'end'})")
    driver.save_screenshot(os.path.join(os.path.dirname(SHOT_DIR[0]), 'cube_live.png'))
    # The live lag while the cube ran (and the studio drew its AR view, at
    # nice 10): reported, the live case holds the targets.
    lags = sorted(driver.execute_script('return window.kinemoStudio.lags()'))
    if lags:
        print(f'cube: live motion lag over {len(lags)} frames: p50 {lags[len(lags) // 2]:.1f} ms, '
              f'p99 {lags[min(len(lags) - 1, int(len(lags) * 0.99))]:.1f} ms; AR view: '
              f'{driver.execute_script("return window.kinemoStudio.cube()")["ar"]["caption"]!r}')
    driver.find_element(By.ID, 'live').click()  # stop the microphone
    wait_for(driver, 'the microphone to stop', lambda s: not s['playing'], 10)
    # The 12 s video ends: the cube detaches by itself, and the page says why.
    wait_for_text(driver, 'cube-status', 'not attached (source ended)', 30)
    check_cube_ar(driver, url)
    # A WAV is no cube video: refused, naming the field.
    wav = os.path.join(source, 'tests/data/speech', SPEECH)
    driver.find_element(By.ID, 'cube-file').send_keys(wav)
    driver.find_element(By.ID, 'cube-attach').click()
    bad = wait_cube(driver, 'the refusal', lambda c: c['status'].startswith('attach_cube.'), 20)
    print(f'cube: a WAV as the video: {bad["status"]}')
    check(bad['status'].startswith('attach_cube.upload: ') and not bad['attached'], bad['status'])
    # The rendered video (the studio's, from its cube_dir) uploaded as the
    # user's own with its camera; a streamed recording follows it.
    driver.execute_script("document.getElementById('cube-file').value = ''")
    rendered = os.path.join(STACK[0].cube_dir, 'bundled', 'tone_scenario')
    driver.find_element(By.ID, 'cube-file').send_keys(rendered + '.avi')
    driver.find_element(By.ID, 'cube-camera').send_keys(rendered + '.camera.yaml')
    driver.find_element(By.ID, 'cube-attach').click()
    up = wait_cube(driver, 'the uploaded cube attached', lambda c: c['attached'] and
                   c['status'].startswith('tone_scenario.avi attached to'), 60)
    check(up['session_id'] == angry['session_id'], f'the upload went to session {up["session_id"]}')
    check(up['face'] in ('pos_z', 'neg_z'), f'the uploaded cube\'s face at attach: {up}')
    uploads = os.listdir(os.path.join(STACK[0].cube_dir, 'uploads'))
    check(len(uploads) == 2, f'the studio keeps the upload and its camera: {uploads}')
    Select(driver.find_element(By.ID, 'wav-sample')).select_by_visible_text(SPEECH)
    driver.find_element(By.ID, 'cube-play').click()
    # The caption names the recording that streams, not the microphone.
    recording = driver.execute_script("return document.getElementById('wav-sample').selectedOptions[0].textContent")
    named = wait_cube(driver, f'the live caption naming {recording}', lambda c: c['live_caption'] == f'live: {recording}',
                      20)
    print(f'cube: streaming {recording!r}: caption {named["live_caption"]!r}, status {named["live_status"]!r}')
    check('microphone' not in named['live_status'], f'the status names the microphone: {named["live_status"]!r}')
    streamed = wait_cube(driver, 'two tones from the uploaded cube', lambda c: len(set(c['tones_shown'])) >= 2, 40)
    print(f'cube: uploaded video, recording streamed: tones shown {streamed["tones_shown"]}, faces shown '
          f'{streamed["faces_shown"]}')
    wait_for(driver, 'the recording to end', lambda s: not s['playing'], 30)
    # Detach (the 12 s video still plays: the recording is 7.1 s).
    driver.find_element(By.ID, 'cube-detach').click()
    gone = wait_cube(driver, 'the upload detached', lambda c: not c['attached'] and c['status'].startswith('detached'),
                     20)
    check(os.listdir(os.path.join(STACK[0].cube_dir, 'uploads')) == [], 'the upload was not removed on detach')
    check(not gone['ar']['shown'] and gone['ar']['caption'] == '', f'the AR view after Detach: {gone["ar"]}')
    errors = console_errors(driver)
    check(not errors, f'console errors: {errors}')


def fetch_status(driver, path):
    """GET `path` from the page (with its cookie): [status, content type, bytes]."""
    return driver.execute_async_script('''
        const done = arguments[arguments.length - 1];
        fetch(arguments[0]).then(async (r) => done([r.status, r.headers.get('content-type'),
                                                    (await r.arrayBuffer()).byteLength]))
          .catch((e) => done([0, String(e), 0]));''', path)


BEARER = {}


def check_cube_ar(driver, url):
    """The AR view of the bundled video: drawn by the studio after the attach
    (at a low CPU priority, so mostly after the 12 s video has ended),
    shown in the cube panel's <video>, decoded and playing; its route needs
    the token and takes AR video names only."""
    got = wait_cube(driver, 'the AR view loaded', lambda c: c['ar']['shown'] and c['ar']['ready_state'] >= 2 and
                    c['ar']['video_width'] > 0, 240)
    ar = got['ar']
    print(f'cube: AR view {ar["url"]}: {ar["video_width"]}x{ar["video_height"]}, readyState {ar["ready_state"]}; '
          f'caption {ar["caption"]!r}')
    check(ar['url'] == '/cube/ar/bundled/tone_scenario.webm' and (ar['video_width'], ar['video_height']) == (640, 480)
          and ar['error'] == 0, f'the AR view: {ar}')
    playing = wait_cube(driver, 'the AR view playing',
                        lambda c: not c['ar']['paused'] and c['ar']['current_time_s'] > ar['current_time_s'] + 0.5, 30)
    print(f'cube: AR view playing at {playing["ar"]["current_time_s"]:.2f} s')
    driver.execute_script("document.getElementById('cube-ar').scrollIntoView({block: 'center'})")
    driver.save_screenshot(os.path.join(os.path.dirname(SHOT_DIR[0]), 'cube_ar.png'))
    # The video itself beside the screenshots, to look at.
    shutil.copyfile(os.path.join(STACK[0].cube_dir, 'bundled', 'tone_scenario.ar.webm'),
                    os.path.join(os.path.dirname(SHOT_DIR[0]), 'cube_ar.webm'))
    status, kind, size = fetch_status(driver, ar['url'])
    check(status == 200 and kind == 'video/webm' and size > 100000,
          f'GET {ar["url"]} with the cookie: {status} {kind} {size}')
    # Without the token, and names that are not AR videos (with the token, as
    # a script sends it; not from the page, whose console stays clean).
    for path, headers, want in ((ar['url'], {}, 401),
                                ('/cube/ar/bundled/%2e%2e%2ftone_scenario.avi', BEARER, 400),
                                ('/cube/ar/bundled/..%2F..%2Fstudio.webm', BEARER, 400),
                                ('/cube/ar/uploads/tone_scenario.ar.webm', BEARER, 400),
                                ('/cube/ar/bundled/no_such_scenario.webm', BEARER, 404)):
        try:
            with urllib.request.urlopen(urllib.request.Request(url.rstrip('/') + path, headers=headers),
                                        timeout=10) as r:
                status = r.status
        except urllib.error.HTTPError as e:
            status = e.code
        check(status == want, f'GET {path} {"with" if headers else "without"} the token: {status}, not {want}')
    print(f'cube: {ar["url"]} {size} bytes with the cookie, 401 without the token, 400 for traversal names, '
          '404 unknown')


def wait_for_text(driver, element_id, text, timeout_s):
    wait_for_status(driver, element_id, lambda got: got == text, timeout_s)


CASES = {'page': case_page, 'live': case_live, 'character': case_character, 'vleo': case_vleo, 'cube': case_cube,
         'face': case_face}
SHOT_DIR = ['']
STACK = [None]


def main():
    if len(sys.argv) != 4 or sys.argv[1] not in CASES:
        print(__doc__)
        return 2
    case, source, build = sys.argv[1], os.path.abspath(sys.argv[2]), os.path.abspath(sys.argv[3])
    artifacts = os.path.join(build, 'test-artifacts', 'studio')
    os.makedirs(artifacts, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix=f'studio-{case}-')
    stack = Stack(build, tmp)
    driver = None
    try:
        fake_audio = os.path.join(source, 'tests/data/speech', SPEECH) if case in ('live', 'cube', 'face') else None
        try:
            driver = start_browser(tmp, fake_audio)
        except WebDriverException as e:
            print(f'SKIP: Chromium cannot start: {e.msg}')
            return SKIP
        SHOT_DIR[0] = os.path.join(artifacts, f'{case}.png')
        # The character case uploads a GLB (800 KB, base64 inside one
        # message), the cube case a cube video (18 MB).
        url = start_stack(stack, source, build, with_robot=(case == 'vleo'),
                          max_upload_bytes={'character': 8 << 20, 'cube': 32 << 20}.get(case, 1 << 20),
                          cube=(case == 'cube'))
        STACK[0] = stack
        BEARER['Authorization'] = f'Bearer {stack.token}'
        print(f'studio at {url}')
        # The token once in the URL, as `kinemo studio` prints it: the studio
        # answers with its cookie, which the case's pages then carry.
        driver.get(f'{url}?token={stack.token}')
        try:
            CASES[case](driver, url, source)
        finally:
            shot = os.path.join(artifacts, f'{case}.png')
            driver.save_screenshot(shot)
            print(f'screenshot: {shot}')
        print(f'PASS: studio {case}')
        return 0
    except Fail as e:
        print(f'FAIL: {e}')
        for name, _ in stack.procs:
            print(f'--- {name} log (tail) ---\n{stack.log(name)[-3000:]}')
        return 1
    finally:
        if driver is not None:
            driver.quit()
        stack.stop()
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == '__main__':
    sys.exit(main())
