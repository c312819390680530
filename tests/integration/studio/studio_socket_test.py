#!/usr/bin/python3
"""The studio's socket without a browser (python3-websocket), against a real
stack on loopback (the studio in front of kinemo_allinone and a simulated
Pleo):

  - the first frame is `hello`;
  - bad messages (not JSON, a binary frame, an unknown call, a bad value, a
    chunk of a stream that was never started, a value the coordinator
    refuses) each get an error frame naming the field, and the socket stays
    usable;
  - a page of another origin cannot open the socket (HTTP 403);
  - Animate answers with a BVH; export_motion writes it with its face on
    the chosen character: a VRM Animation for Godette, the man's GLB with
    the animation; a VRMA for a GLB character, no format or a bad BVH are
    refused naming the field;
  - StreamAnimate over the socket (PCM chunks of
    a bundled WAV) answers with a header, frames, a summary and `ended`;
  - a session's WatchSession streams its snapshot and ends on `cancel`;
  - a message over max_upload_bytes closes the socket with 1009;
  - sockets reset while their answers are still being written (the page
    stopped reading and went away) leave the studio serving.

    studio_socket_test.py SOURCE_DIR BUILD_DIR
"""
import base64
import json
import os
import socket
import struct
import sys
import urllib.request
import wave

import websocket

from studio_stack import SPEECH, Fail, answer, check, run_with_stack


def connect(url, token, origin=None):
    ws = websocket.create_connection(url, timeout=60, origin=origin, header=[f'Authorization: Bearer {token}'])
    hello = json.loads(ws.recv())
    check('hello' in hello and hello['id'] == 0, f'first frame is not hello: {hello}')
    return ws, hello['hello']


def send(ws, message):
    ws.send(json.dumps(message))


def expect_error(ws, call_id, message, field):
    if isinstance(message, bytes):
        ws.send_binary(message)
    else:
        ws.send(message if isinstance(message, str) else json.dumps(message))
    m = answer(ws, call_id)
    check('error' in m, f'{message!r:.80}: no error frame but {m}')
    check(m['error']['message'].startswith(field),
          f'{message!r:.80}: error does not start with {field!r}: {m["error"]}')
    print(f'  {str(message)[:70]!r} -> {m["error"]["code"]}: {m["error"]["message"][:90]}')


def run(source, url, token):
    ws_url = url.replace('http://', 'ws://') + 'ws'
    ws, hello = connect(ws_url, token, origin=url.rstrip('/'))
    check(int(hello['maxUploadBytes']) == 1048576, f'hello: {hello}')

    print('bad messages:')
    expect_error(ws, 0, 'not json', 'message:')
    expect_error(ws, 0, b'\x00\x01binary', 'message:')
    expect_error(ws, 5, {'id': 5, 'dance': {}}, 'dance:')
    expect_error(ws, 6, {'id': 6, 'act': {'intensity': 'loud'}}, 'act.intensity')
    expect_error(ws, 7, {'id': 7, 'stream': {'chunk': {'sequenceNumber': 0, 'data': ''}}}, 'stream:')
    expect_error(ws, 8, {'id': 8, 'streamEnd': {}}, 'stream_end:')
    expect_error(ws, 9, {'id': 9, 'act': {'sessionId': 'nosuch', 'action': 'ACTION_KISSES', 'intensity': 7}},
                 'act.')
    send(ws, {'id': 10, 'listSessions': {}})
    check('listSessions' in answer(ws, 10), 'the socket is not usable after the errors')

    print('origin:')
    try:
        websocket.create_connection(ws_url, timeout=10, origin='http://evil.example',
                                    header=[f'Authorization: Bearer {token}'])
        raise Fail('a page of another origin opened the socket')
    except websocket.WebSocketBadStatusException as e:
        check(e.status_code == 403, f'another origin got HTTP {e.status_code}, not 403')
        print('  http://evil.example -> 403')

    print('animate:')
    with open(os.path.join(source, 'tests/data/speech', SPEECH), 'rb') as f:
        wav_bytes = f.read()
    send(ws, {'id': 11, 'animate': {'audio': {'format': {'encoding': 'AUDIO_ENCODING_FILE'},
                                              'data': base64.b64encode(wav_bytes).decode()},
                                    'method': 'METHOD_BODYSPEECH'}})
    m = answer(ws, 11)
    check('animate' in m, f'animate: {str(m)[:300]}')
    bvh = base64.b64decode(m['animate']['motion']['bvh']).decode()
    check(bvh.startswith('HIERARCHY'), f'animate: not a BVH: {bvh[:40]!r}')
    print(f'  {len(bvh)} bytes of BVH, {len(m["animate"]["prosody"].get("accents", []))} accents')

    print('export on the character:')
    # On a socket of its own: a socket with a character also gets its streams'
    # frames on it (character_motion), which the stream below does not expect.
    wx, _ = connect(ws_url, token)
    face = m['animate'].get('face')
    check(face and len(face.get('frames', [])) > 0, 'animate: no face track')
    export = {'bvh': base64.b64encode(bvh.encode()).decode(), 'name': 'speech.bvh', 'face': face,
              'format': 'EXPORT_FORMAT_VRMA'}
    expect_error(wx, 20, {'id': 20, 'exportMotion': export}, 'export_motion:')  # no character yet
    send(wx, {'id': 21, 'character': {'bundled': 'godette.vrm'}})
    info = answer(wx, 21)['character']
    check(info.get('format') == 'vrm0', f'Godette\'s format: {info.get("format")}')
    send(wx, {'id': 22, 'exportMotion': export})
    got = answer(wx, 22)
    check('exportedFile' in got, f'export_motion: {str(got)[:300]}')
    data = base64.b64decode(got['exportedFile']['data'])
    check(got['exportedFile']['fileName'] == 'speech.vrma' and data[:4] == b'glTF', f'{got["exportedFile"]["fileName"]}, '
          f'{data[:4]!r}')
    doc = json.loads(data[20:20 + struct.unpack('<I', data[12:16])[0]])
    ext = doc['extensions']['VRMC_vrm_animation']
    check(len(ext['humanoid']['humanBones']) >= 45 and 'aa' in ext['expressions']['preset'] and 'meshes' not in doc,
          f'the VRMA: {len(ext["humanoid"]["humanBones"])} bones, {ext.get("expressions")}')
    print(f'  Godette: {got["exportedFile"]["fileName"]}, {len(data)} bytes, {len(ext["humanoid"]["humanBones"])} bones, '
          f'expressions {sorted(ext["expressions"]["preset"])}')
    send(wx, {'id': 23, 'character': {'bundled': 'quaternius_man_casual.glb'}})
    check(answer(wx, 23)['character'].get('format') == 'glb', 'the man is a GLB')
    expect_error(wx, 24, {'id': 24, 'exportMotion': export}, 'export_motion.format')
    expect_error(wx, 25, {'id': 25, 'exportMotion': dict(export, format='EXPORT_FORMAT_UNSPECIFIED')},
                 'export_motion.format')
    expect_error(wx, 26, {'id': 26, 'exportMotion': dict(export, format='EXPORT_FORMAT_GLB', bvh='bm90IGEgQlZI')},
                 'export_motion.bvh')
    send(wx, {'id': 27, 'exportMotion': dict(export, format='EXPORT_FORMAT_GLB')})
    got = answer(wx, 27)
    check('exportedFile' in got, f'export_motion GLB: {str(got)[:300]}')
    data = base64.b64decode(got['exportedFile']['data'])
    doc = json.loads(data[20:20 + struct.unpack('<I', data[12:16])[0]])
    check(got['exportedFile']['fileName'] == 'speech.glb' and doc.get('meshes') and doc['animations'][0]['name'] == 'kinemo',
          f'the GLB: {got["exportedFile"]["fileName"]}, {len(doc.get("meshes", []))} meshes')
    print(f'  the man: {got["exportedFile"]["fileName"]}, {len(data)} bytes, {len(doc["meshes"])} meshes, '
          f'{len(doc["animations"][0]["channels"])} channels')
    wx.close()

    print('stream:')
    with wave.open(os.path.join(source, 'tests/data/speech', SPEECH)) as w:
        check(w.getframerate() == 16000 and w.getsampwidth() == 2 and w.getnchannels() == 1, 'WAV format')
        pcm = w.readframes(w.getnframes())
    send(ws, {'id': 12, 'stream': {'config': {'format': {'encoding': 'AUDIO_ENCODING_PCM_S16LE',
                                                         'sampleRateHz': 16000, 'channels': 1},
                                              'method': 'METHOD_GESTURE_CONTROLLER'}}})
    chunk = 640  # 20 ms
    seconds = 3
    for seq in range(seconds * 50):
        data = pcm[seq * chunk:(seq + 1) * chunk]
        send(ws, {'id': 12, 'stream': {'chunk': {'sequenceNumber': seq, 'data': base64.b64encode(data).decode()}}})
    send(ws, {'id': 12, 'streamEnd': {}})
    kinds, frames = [], 0
    while True:
        m = answer(ws, 12)
        check('error' not in m, f'stream: {m}')
        if 'ended' in m:
            break
        kind = next(k for k in m['stream'] if k in ('header', 'frames', 'accent', 'keyword', 'visemes', 'summary'))
        if not kinds or kinds[-1] != kind:
            kinds.append(kind)
        if kind == 'frames':
            frames += len(m['stream']['frames'].get('frames', []))
    check(kinds[0] == 'header' and kinds[-1] == 'summary' and 'frames' in kinds, f'stream messages: {kinds}')
    check(abs(frames - 30 * seconds) <= 2, f'{frames} frames for {seconds} s of audio at 30 fps')
    print(f'  {kinds}, {frames} frames for {seconds} s')

    print('sessions:')
    send(ws, {'id': 13, 'openSession': {'robotId': 'pleo', 'initialEmotion': 'EMOTION_ANGRY'}})
    m = answer(ws, 13)
    check('openSession' in m, f'open_session: {m}')
    session = m['openSession']['session']['sessionId']
    send(ws, {'id': 14, 'watchSession': {'sessionId': session}})
    m = answer(ws, 14)
    check(m.get('sessionEvent', {}).get('snapshot', {}).get('emotion') == 'EMOTION_ANGRY', f'watch: {m}')
    send(ws, {'id': 14, 'cancel': {}})
    while 'ended' not in m:
        m = answer(ws, 14)
        check('error' not in m, f'cancelled watch: {m}')
    print(f'  {session}: watch snapshot angry, cancelled -> ended')

    print('too big:')
    send(ws, {'id': 15, 'animate': {'audio': {'data': 'x' * 1100000}}})
    op, data = ws.recv_data(control_frame=True)
    while op != websocket.ABNF.OPCODE_CLOSE:
        op, data = ws.recv_data(control_frame=True)
    code = int.from_bytes(data[:2], 'big')
    check(code == 1009, f'an oversized message closed the socket with {code}')
    print('  1.4 MB message -> close 1009')
    # The studio still serves new sockets.
    ws2, _ = connect(ws_url, token)
    send(ws2, {'id': 1, 'listSessions': {}})
    check('listSessions' in answer(ws2, 1), 'a new socket after the 1009 close does not work')
    ws2.close()

    print('reset mid-write:')
    # Thousands of bad messages queue thousands of error frames; the client
    # reads none, so the studio's write blocks on a full socket, and then
    # the connection is reset (RST): the read fails while a write is in
    # flight. The studio must drop the queue without touching the frame the
    # write still holds.
    frames = 0
    for _ in range(4):
        wr, _ = connect(ws_url, token)
        for _ in range(15000):
            wr.send('not json')
        frames += 15000
        wr.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack('ii', 1, 0))
        wr.sock.close()
    with urllib.request.urlopen(url + 'healthz', timeout=10) as r:
        check(r.status == 200, f'/healthz after the resets: HTTP {r.status}')
    ws3, _ = connect(ws_url, token)
    send(ws3, {'id': 1, 'listSessions': {}})
    check('listSessions' in answer(ws3, 1), 'a new socket after the resets does not work')
    ws3.close()
    print(f'  4 sockets reset with {frames} answers queued; the studio still serves')

    print('metrics:')
    request = urllib.request.Request(url + 'metrics', headers={'Authorization': f'Bearer {token}'})
    with urllib.request.urlopen(request, timeout=10) as r:
        text = r.read().decode()
    values = {}
    for line in text.splitlines():
        if line.startswith('kinemo_studio_'):
            name, value = line.rsplit(' ', 1)
            values[name] = float(value)
    check(values.get('kinemo_studio_sockets_opened_total', 0) >= 2, f'sockets opened: {values}')
    check(values.get('kinemo_studio_messages_total', 0) >= 10, f'messages: {values}')
    check(values.get('kinemo_studio_messages_refused_total', 0) >= 1, f'refused: {values}')
    print(f'  GET /metrics: {values}')


def main():
    return run_with_stack(__doc__, 'socket', lambda source, build, url, stack: run(source, url, stack.token),
                          with_robot=True, errors=(websocket.WebSocketException,))


if __name__ == '__main__':
    sys.exit(main())
