#!/usr/bin/python3
"""The studio's authentication (StudioAuth) against a real stack on loopback
(the studio in front of kinemo_allinone):

  - without the token every route (each one, GET, HEAD and POST) answers 401
    with WWW-Authenticate, and so does a wrong token; GET /healthz answers
    200 without one;
  - the WebSocket upgrade without the token, or with a wrong one, is refused
    with 401 and opens no socket (the studio's socket counter stays put);
  - `?token=` answers 303 to the same path with an HttpOnly, SameSite=Strict
    cookie, which then opens the page and the socket; so does a Bearer header;
  - 1000 wrong tokens from one address: at most max_failures_per_minute (10)
    are looked at, the rest get 429 with Retry-After, even the right token
    from that address; another address is not affected;
  - the studio binary on 0.0.0.0 without a token exits 2 naming auth.token;
  - with server.tls (deploy/certs.sh's studio.pem/.key) the same over HTTPS
    and WSS: 401 without the token, the page and the socket with it, and the
    cookie is Secure.

    studio_auth_test.py SOURCE_DIR BUILD_DIR
"""
import http.client
import os
import ssl
import subprocess
import sys
import time
import urllib.parse

import websocket

from studio_stack import Fail, check, run_with_stack


def request(port, path, headers=None, method='GET', source='127.0.0.1'):
    conn = http.client.HTTPConnection('127.0.0.1', port, timeout=10, source_address=(source, 0))
    try:
        conn.request(method, path, headers=headers or {})
        r = conn.getresponse()
        return r.status, dict(r.getheaders()), r.read()
    finally:
        conn.close()


def sockets_opened(port, token):
    _, _, body = request(port, '/metrics', {'Authorization': f'Bearer {token}'})
    for line in body.decode().splitlines():
        if line.startswith('kinemo_studio_sockets_opened_total'):
            return float(line.rsplit(' ', 1)[1])
    return 0.0


def run(source, build, url, token, tmp):
    port = urllib.parse.urlparse(url).port
    status, _, body = request(port, '/healthz')
    check(status == 200 and b'SERVING' in body, f'/healthz without the token: {status} {body[:100]}')
    print('  GET /healthz without the token -> 200')

    routes = ['/', '/index.html', '/static/studio.js', '/static/studio.css', '/static/capture-worklet.js',
              '/libs/kinemo-libs.js', '/samples/', '/samples/sense_and_sensibility_01_austen_64kb-0870.wav',
              '/metrics', '/ws', '/nowhere', '/static/../../etc/passwd', '/cube/ar/bundled/tone_scenario.webm',
              '/cube/ar/bundled/%2e%2e%2fsecret.webm']
    for path in routes:
        for method in ('GET', 'HEAD', 'POST'):
            status, h, _ = request(port, path, method=method)
            check(status == 401, f'{method} {path} without the token: {status}')
            check(h.get('WWW-Authenticate', '').startswith('Bearer'), f'{method} {path}: {h}')
    print(f'  {len(routes)} routes x GET/HEAD/POST without the token -> 401')
    # A wrong token, and a wrong cookie, on each route (each from its own
    # address: the throttle is tested below).
    for i, path in enumerate(routes):
        for j, headers in enumerate(({'Authorization': 'Bearer wrong-token-wrong-token'},
                                     {'Cookie': f'kinemo-studio-{port}=wrong-token-wrong-token'})):
            status, _, _ = request(port, path, headers, source=f'127.0.{j + 1}.{i + 1}')
            check(status == 401, f'GET {path} with {headers}: {status}')
    print('  wrong Bearer token / wrong cookie on each route -> 401')

    opened = sockets_opened(port, token)
    ws_url = url.replace('http://', 'ws://') + 'ws'
    for header in ([], ['Authorization: Bearer wrong-token-wrong-token'], [f'Cookie: kinemo-studio-{port}=nope']):
        try:
            websocket.create_connection(ws_url, timeout=10, header=header, origin=url.rstrip('/'))
            raise Fail(f'the socket opened without the token ({header})')
        except websocket.WebSocketBadStatusException as e:
            check(e.status_code == 401, f'socket without the token ({header}): HTTP {e.status_code}')
    check(sockets_opened(port, token) == opened, 'a refused upgrade opened a socket')
    print('  WebSocket upgrade without / with a wrong token -> 401, no socket opened')

    # ?token= -> 303 + cookie -> the page and the socket.
    status, h, _ = request(port, f'/?token={token}')
    check(status == 303 and h.get('Location') == '/', f'?token=: {status} {h}')
    cookie = h.get('Set-Cookie', '')
    for part in (f'kinemo-studio-{port}={token}', 'HttpOnly', 'SameSite=Strict', 'Path=/'):
        check(part in cookie, f'Set-Cookie lacks {part}: {cookie}')
    jar = cookie.split(';', 1)[0]
    status, _, body = request(port, '/', {'Cookie': jar})
    check(status == 200 and b'<title>kinemo studio</title>' in body, f'the page with the cookie: {status}')
    status, _, _ = request(port, '/static/studio.js', {'Authorization': f'Bearer {token}'})
    check(status == 200, f'the script with the Bearer token: {status}')
    ws = websocket.create_connection(ws_url, timeout=10, header=[f'Cookie: {jar}'], origin=url.rstrip('/'))
    check('hello' in ws.recv(), 'no hello on the socket opened with the cookie')
    ws.close()
    print('  ?token= -> 303 + HttpOnly SameSite=Strict cookie -> page 200, socket open; Bearer -> 200')

    # Brute force: 1000 wrong tokens on one connection from 127.0.0.5.
    conn = http.client.HTTPConnection('127.0.0.1', port, timeout=10, source_address=('127.0.0.5', 0))
    counts, retry_after = {}, None
    t0 = time.monotonic()
    for i in range(1000):
        conn.request('GET', '/', headers={'Authorization': f'Bearer guess{i:06d}guess{i:06d}'})
        r = conn.getresponse()
        r.read()
        counts[r.status] = counts.get(r.status, 0) + 1
        if r.status == 429:
            retry_after = r.getheader('Retry-After')
    elapsed = time.monotonic() - t0
    conn.close()
    check(counts.get(401, 0) <= 10, f'more than 10 wrong tokens were looked at: {counts}')
    check(counts.get(429, 0) >= 990, f'the wrong tokens were not throttled: {counts}')
    check(retry_after is not None and int(retry_after) >= 1, f'Retry-After: {retry_after}')
    status, _, _ = request(port, '/', {'Authorization': f'Bearer {token}'}, source='127.0.0.5')
    check(status == 429, f'the right token from a throttled address: {status}, not 429')
    status, _, _ = request(port, '/', {'Authorization': f'Bearer {token}'}, source='127.0.0.6')
    check(status == 200, f'the right token from another address: {status}')
    print(f'  1000 wrong tokens in {elapsed:.2f} s: {counts} (Retry-After {retry_after} s); '
          'right token: 429 from that address, 200 from another')

    # On a non-loopback address the studio needs a configured token.
    config = os.path.join(tmp, 'open.textproto')
    with open(config, 'w') as f:
        f.write('coordinator { address: "127.0.0.1:1" }\n')
    r = subprocess.run([os.path.join(build, 'services/studio/studio'), '--config', config, '--host', '0.0.0.0',
                        '--port', '0'], capture_output=True, text=True, timeout=30)
    check(r.returncode == 2 and 'auth.token' in r.stderr, f'studio --host 0.0.0.0: {r.returncode} {r.stderr}')
    print(f'  studio --host 0.0.0.0 without a token -> 2: {r.stderr.strip()[:100]}')


def run_tls(source, build, stack, tmp):
    certs = os.path.join(tmp, 'certs')
    subprocess.run(['bash', os.path.join(source, 'deploy/certs.sh'), certs], check=True, capture_output=True,
                   timeout=60)
    config = os.path.join(tmp, 'studio-tls.textproto')
    with open(config, 'w') as f:
        f.write('coordinator { address: "%s" }\nauth { token: "%s" }\n'
                'server { tls { cert_file: "%s/studio.pem" key_file: "%s/studio.key" } }\n'
                % (stack.coordinator, stack.token, certs, certs))
    port_file = os.path.join(tmp, 'studio-tls.port')
    proc = stack.spawn('studio-tls', [os.path.join(build, 'services/studio/studio'), '--config', config,
                                      '--port', '0', '--port-file', port_file])
    port = stack.port('studio-tls', proc, port_file)
    context = ssl.create_default_context(cafile=os.path.join(certs, 'ca.pem'))

    def get(path, headers=None):
        conn = http.client.HTTPSConnection('127.0.0.1', port, timeout=10, context=context)
        try:
            conn.request('GET', path, headers=headers or {})
            r = conn.getresponse()
            return r.status, dict(r.getheaders()), r.read()
        finally:
            conn.close()

    status, _, body = get('/healthz')
    check(status == 200 and b'SERVING' in body, f'https /healthz: {status} {body[:100]}')
    status, _, _ = get('/')
    check(status == 401, f'https / without the token: {status}')
    status, _, body = get('/', {'Authorization': f'Bearer {stack.token}'})
    check(status == 200 and b'<title>kinemo studio</title>' in body, f'https / with the token: {status}')
    status, h, _ = get(f'/?token={stack.token}')
    check(status == 303 and 'Secure' in h.get('Set-Cookie', ''), f'https ?token=: {status} {h}')
    ws = websocket.create_connection(f'wss://127.0.0.1:{port}/ws', timeout=10,
                                     sslopt={'ca_certs': os.path.join(certs, 'ca.pem')},
                                     header=[f'Authorization: Bearer {stack.token}'])
    check('hello' in ws.recv(), 'no hello on the WSS socket')
    ws.close()
    try:
        websocket.create_connection(f'wss://127.0.0.1:{port}/ws', timeout=10,
                                    sslopt={'ca_certs': os.path.join(certs, 'ca.pem')})
        raise Fail('the WSS socket opened without the token')
    except websocket.WebSocketBadStatusException as e:
        check(e.status_code == 401, f'WSS without the token: HTTP {e.status_code}')
    print(f'  HTTPS/WSS on 127.0.0.1:{port} (deploy/certs.sh studio.pem): healthz 200, / 401 -> 200 with the '
          'token, Secure cookie, WSS hello with the token, 401 without')


def main():
    def body(source, build, url, stack):
        run(source, build, url, stack.token, stack.tmp)
        run_tls(source, build, stack, stack.tmp)
    return run_with_stack(__doc__, 'auth', body, with_robot=False, errors=(websocket.WebSocketException,))


if __name__ == '__main__':
    sys.exit(main())
