#!/usr/bin/env python3
"""The deployed studio attaches a bundled cube video out of the box.

  studio_cube_check.py STUDIO_URL TOKEN_FILE [CA_FILE]

Over the studio's WebSocket (python3-websocket): its hello lists at least one
bundled cube scenario (deploy/config/studio.textproto sets cube_dir; the cube
data is beside the binary or in the source tree); a session opened through
the socket attaches the first one (the studio draws it into cube_dir, which
the cube tracker reads inside its file_root: the volume compose shares, the
local stack's var/media), and AttachCube's answer already carries the cube's
first face. Detaches and closes the session it opened. Exit 1 with FAIL on
any miss.
"""
import json
import os
import ssl
import sys

import websocket

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'studio'))
from studio_stack import answer  # noqa: E402  (the studio tests' socket helper)


def fail(message):
    print(f'FAIL: studio cube: {message}')
    sys.exit(1)


def call(ws, call_id, name, body):
    ws.send(json.dumps({'id': call_id, name: body}))
    m = answer(ws, call_id)
    if 'error' in m:
        fail(f'{name}: {m["error"]}')
    return m


def main():
    url = sys.argv[1].rstrip('/')
    with open(sys.argv[2]) as f:
        token = f.read().strip()
    sslopt = {'ca_certs': sys.argv[3], 'cert_reqs': ssl.CERT_REQUIRED} if len(sys.argv) > 3 else None
    ws_url = url.replace('http', 'ws', 1) + '/ws'
    ws = websocket.create_connection(ws_url, timeout=120, origin=url, sslopt=sslopt,
                                     header=[f'Authorization: Bearer {token}'])
    hello = json.loads(ws.recv()).get('hello', {})
    scenarios = hello.get('cubeScenarios', [])
    if not scenarios:
        fail(f'the studio offers no bundled cube video (hello: {hello})')
    opened = call(ws, 1, 'openSession', {'robotId': 'pleo', 'initialEmotion': 'EMOTION_NEUTRAL'})
    session = opened['openSession']['session']['sessionId']
    try:
        attached = call(ws, 2, 'attachCube', {'sessionId': session, 'bundled': scenarios[0]})
        s = attached['attachCube']['session']
        if not s.get('cubeAttached') or s.get('cubeFace', 'CUBE_FACE_UNSPECIFIED') == 'CUBE_FACE_UNSPECIFIED':
            fail(f'{scenarios[0]} attached without its first face: {s}')
        print(f'studio cube: {len(scenarios)} bundled ({", ".join(scenarios)}); {scenarios[0]} attached to '
              f'{session}, first face {s["cubeFace"]}')
        call(ws, 3, 'detachCube', {'sessionId': session})
    finally:
        call(ws, 4, 'closeSession', {'sessionId': session})
        ws.close()


if __name__ == '__main__':
    main()
