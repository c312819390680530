"""A real stack for the studio's tests: pleo_sim (optional), kinemo_allinone
with the bundled gesture library and models, and the studio in front of it,
on loopback with ephemeral ports (--port 0 --port-file), health-checked;
stop() ends only the processes started here. The studio's token (StudioAuth)
is a new random one per stack: `stack.token`."""
import json
import os
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request

SPEECH = 'sense_and_sensibility_01_austen_64kb-0870.wav'


class Fail(Exception):
    pass


def check(condition, message):
    if not condition:
        raise Fail(message)


class Stack:
    """The processes this test started, stopped in reverse order."""

    def __init__(self, build, tmp):
        self.build, self.tmp, self.procs = build, tmp, []
        self.token = secrets.token_hex(24)

    def spawn(self, name, argv):
        log = open(os.path.join(self.tmp, name + '.log'), 'wb')
        proc = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        self.procs.append((name, proc))
        return proc

    def port(self, name, proc, port_file, timeout_s=60):
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                raise Fail(f'{name} exited with {proc.returncode}: {self.log(name)[-2000:]}')
            try:
                with open(port_file) as f:
                    text = f.read().strip()
                if text:
                    return int(text)
            except FileNotFoundError:
                pass
            time.sleep(0.05)
        raise Fail(f'{name} wrote no port file in {timeout_s} s')

    def log(self, name):
        try:
            with open(os.path.join(self.tmp, name + '.log'), errors='replace') as f:
                return f.read()
        except OSError:
            return ''

    def stop(self):
        for _, proc in reversed(self.procs):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()


def answer(ws, call_id):
    """The next socket frame for `call_id` (frames of other calls are skipped)."""
    while True:
        m = json.loads(ws.recv())
        if m.get('id', 0) == call_id:
            return m


def run_with_stack(doc, name, body, with_robot, errors=()):
    """The main() of a studio test run as `TEST SOURCE_DIR BUILD_DIR`: a stack
    in a temporary folder, body(source, build, url, stack), the processes'
    logs on failure; returns the exit code."""
    if len(sys.argv) != 3:
        print(doc)
        return 2
    source, build = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
    tmp = tempfile.mkdtemp(prefix=f'studio-{name}-')
    stack = Stack(build, tmp)
    try:
        url = start_stack(stack, source, build, with_robot=with_robot)
        print(f'studio at {url}')
        body(source, build, url, stack)
        print(f'PASS: studio {name}')
        return 0
    except (Fail, OSError, subprocess.SubprocessError) + tuple(errors) as e:
        print(f'FAIL: {e}')
        for proc_name, _ in stack.procs:
            print(f'--- {proc_name} log (tail) ---\n{stack.log(proc_name)[-3000:]}')
        return 1
    finally:
        stack.stop()
        shutil.rmtree(tmp, ignore_errors=True)


def start_stack(stack, source, build, with_robot, max_upload_bytes=1048576, cube=False, static_dir=''):
    """cube: the stack of the cube (issue 24), as cube_tones_test has it: the
    bundled store's models (its controller carries the tones), Pleo's emotion
    model at rate 1.0/s, a cube tracker reading the studio's cube_dir
    (TMP/cube, stack.cube_dir).
    `static_dir`: the page's files to serve instead of the build's (a bench compares pages)."""
    tmp = stack.tmp
    robot = ''
    if with_robot or cube:
        sim_port_file = os.path.join(tmp, 'pleo_sim.port')
        sim = stack.spawn('pleo_sim', [os.path.join(build, 'services/pleo_sim/pleo_sim'), '--tcp', '127.0.0.1:0',
                                       '--port-file', sim_port_file] + (['--switch-ms', '100'] if cube else []))
        sim_port = stack.port('pleo_sim', sim, sim_port_file)
        robot = ('robot_bridge { robots { robot_id: "pleo" tcp { host: "127.0.0.1" port: %d } unit_id: 1%s } }\n'
                 % (sim_port, ' timing { poll_s: 0.05 max_backoff_s: 0.2 }' if cube else ''))
    config = os.path.join(tmp, 'allinone.textproto')
    stack.cube_dir = os.path.join(tmp, 'cube')
    with open(config, 'w') as f:
        if cube:
            os.makedirs(stack.cube_dir)
            f.write('coordinator { emotion { rate_per_s: 1.0 } animate { models { inference_model_id: "bundled" '
                    'controller_id: "bundled" } } }\n'
                    'cube_tracker { file_root: "%s" }\n%s' % (stack.cube_dir, robot))
        else:
            f.write('coordinator { animate { default_method: METHOD_BODYSPEECH models { gesture_graph_id: "bundled" '
                    'inference_model_id: "bundled" controller_id: "bundled" } } }\n'
                    'planner {\n  library_root: "%s/tests/data"\n'
                    '  preload { library_id: "bundled" paths: "planner_gesture" paths: "planner_controller" }\n'
                    '  preload_gesture_graphs { graph_id: "bundled" library_id: "bundled" params { stroke_phrases: true } }\n'
                    '}\n%s' % (source, robot))
    aio_port_file = os.path.join(tmp, 'allinone.port')
    # The all-in-one's artifact store in the test's folder (the bundled seed
    # store beside the binary still provides the "bundled" models).
    os.environ['KINEMO_STORE_DIR'] = os.path.join(tmp, 'store')
    aio = stack.spawn('allinone', [os.path.join(build, 'services/allinone/kinemo_allinone'), '--config', config,
                                   '--host', '127.0.0.1', '--port', '0', '--port-file', aio_port_file])
    aio_port = stack.port('allinone', aio, aio_port_file)
    stack.coordinator = f'127.0.0.1:{aio_port}'
    health = subprocess.run([os.path.join(build, 'services/cli/kinemo-health'), f'127.0.0.1:{aio_port}',
                             '--timeout-s', '60'], capture_output=True, text=True)
    check(health.returncode == 0, f'kinemo_allinone not SERVING: {health.stdout}{health.stderr}')
    studio_config = os.path.join(tmp, 'studio.textproto')
    with open(studio_config, 'w') as f:
        # 1 MiB per socket message: the bundled WAVs (<= 230 KB, base64 4/3)
        # fit, the page test's oversized message does not.
        f.write('coordinator { address: "127.0.0.1:%d" }\nmax_upload_bytes: %d\n'
                'sample_dirs: "%s/tests/data/speech"\n'
                'sample_dirs: "%s/tests/data/planner_gesture"\n'
                'sample_dirs: "%s/tests/data/paired/beat2"\n'
                'auth { token: "%s" }\n' % (aio_port, max_upload_bytes, source, source, source, stack.token))
        if static_dir:
            f.write('static_dir: "%s"\n' % static_dir)
        if cube:
            f.write('cube_dir: "%s"\n' % stack.cube_dir)
    studio_port_file = os.path.join(tmp, 'studio.port')
    studio = stack.spawn('studio', [os.path.join(build, 'services/studio/studio'), '--config', studio_config,
                                    '--port', '0', '--port-file', studio_port_file])
    port = stack.port('studio', studio, studio_port_file)
    url = f'http://127.0.0.1:{port}/'
    with urllib.request.urlopen(url + 'healthz', timeout=10) as r:
        body = json.loads(r.read())
    check(body.get('status') == 'SERVING', f'/healthz: {body}')
    return url
