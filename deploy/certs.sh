#!/usr/bin/env bash
# Makes the TLS material for mutual TLS between kinemo's services (openssl):
# a CA, and a certificate + key signed by it for every service and client.
#   deploy/certs.sh [DIR]                 the CA and every certificate (default DIR: ./out/certs)
#   deploy/certs.sh --test-extras [DIR]   also the ones tests use to be refused:
#       expired.pem/.key      a client certificate from the CA whose validity ended in 2021
#       other-ca.pem          another CA, and stranger.pem/.key, a client certificate it signed
#
# DIR then holds ca.pem (give it to every server as server.tls.client_ca_file
# and to every client as its CA), ca.key (keep it there), and NAME.pem /
# NAME.key for NAME in:
#   prosody inference planner cube_tracker robot_bridge coordinator studio
#       server and client certificate (a service is also the client of others,
#       and its health probe presents it); subjectAltName: NAME, NAME with '-'
#       for '_' (Kubernetes service names), localhost, 127.0.0.1, ::1, and
#       $KINEMO_CERT_HOSTS (comma-separated names or IP addresses)
#   cli  client certificate for the kinemo tools (kinemo --ca --cert --key)
#   prometheus  client certificate Prometheus presents to scrape /metrics over
#       mutual TLS (deploy/prometheus/prometheus-tls.yml)
# Idempotent: a certificate that exists, is signed by the CA, is valid for at
# least another day and was made for the same names is kept; the others are
# made again (all of them when the CA itself is missing or expiring).
# Validity: $KINEMO_CERT_DAYS days (default 825). Keys are EC P-256, mode 0600.
# Never commit DIR (out/ is ignored).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
extras=0
if [[ "${1:-}" == --test-extras ]]; then extras=1; shift; fi
if [[ "${1:-}" == -h || "${1:-}" == --help ]]; then sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//'; exit 0; fi
dir="${1:-$root/out/certs}"
days="${KINEMO_CERT_DAYS:-825}"
[[ "$days" =~ ^[0-9]+$ && "$days" -ge 2 && "$days" -le 3650 ]] ||
  { echo "certs: KINEMO_CERT_DAYS: '$days' is not a number of days in [2, 3650]" >&2; exit 2; }
command -v openssl >/dev/null || { echo "certs: openssl is not installed (deploy/install-deps.sh)" >&2; exit 2; }
SERVICES=(prosody inference planner cube_tracker robot_bridge coordinator studio)
CLIENTS=(cli prometheus)

mkdir -p "$dir"
umask 077
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

new_key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }

# make_ca PREFIX CN: a self-signed CA (PREFIX.pem, PREFIX.key).
make_ca() {
  new_key "$tmp/ca.key"
  openssl req -x509 -new -key "$tmp/ca.key" -sha256 -days "$((days + 365))" -subj "/O=kinemo/CN=$2" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" \
    -out "$tmp/ca.pem" 2>/dev/null
  mv "$tmp/ca.key" "$1.key"
  mv "$tmp/ca.pem" "$1.pem"
  chmod 0644 "$1.pem"
}

# The extensions of NAME's certificate: server (and client) for services, client for clients.
extensions() {  # NAME server|client
  local name="$1" san="DNS:$1"
  if [[ "$2" == server ]]; then
    [[ "$name" == *_* ]] && san="$san,DNS:${name//_/-}"
    san="$san,DNS:localhost,IP:127.0.0.1,IP:0:0:0:0:0:0:0:1"
    local h
    IFS=',' read -ra extra <<<"${KINEMO_CERT_HOSTS:-}"
    for h in "${extra[@]}"; do
      h="${h// /}"
      [[ -z "$h" ]] && continue
      if [[ "$h" =~ ^[0-9.]+$ || "$h" == *:* ]]; then san="$san,IP:$h"; else san="$san,DNS:$h"; fi
    done
    printf 'basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature,keyEncipherment\n'
    printf 'extendedKeyUsage=serverAuth,clientAuth\nsubjectAltName=%s\n' "$san"
  else
    printf 'basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\n'
    printf 'extendedKeyUsage=clientAuth\nsubjectAltName=%s\n' "$san"
  fi
}

# issue CA_PREFIX NAME server|client OUT_PREFIX: a key and a certificate signed by the CA.
issue() {
  local ca="$1" name="$2" kind="$3" out="$4"
  extensions "$name" "$kind" >"$tmp/$name.ext"
  new_key "$tmp/$name.key"
  openssl req -new -key "$tmp/$name.key" -subj "/O=kinemo/CN=$name" -out "$tmp/$name.csr" 2>/dev/null
  openssl x509 -req -in "$tmp/$name.csr" -CA "$ca.pem" -CAkey "$ca.key" -CAcreateserial \
    -CAserial "$tmp/ca.srl" -sha256 -days "$days" -extfile "$tmp/$name.ext" -out "$tmp/$name.pem" 2>/dev/null
  mv "$tmp/$name.key" "$out.key"
  mv "$tmp/$name.pem" "$out.pem"
  cp "$tmp/$name.ext" "$out.ext"
  chmod 0644 "$out.pem" "$out.ext"
}

# current NAME KIND: true when DIR/NAME.pem is signed by DIR/ca.pem, valid for
# another day, matches its key and was made with the same extensions.
current() {
  local name="$1" kind="$2"
  [[ -f "$dir/$name.pem" && -f "$dir/$name.key" && -f "$dir/$name.ext" ]] || return 1
  openssl verify -CAfile "$dir/ca.pem" "$dir/$name.pem" >/dev/null 2>&1 || return 1
  openssl x509 -in "$dir/$name.pem" -noout -checkend 86400 >/dev/null 2>&1 || return 1
  [[ "$(openssl x509 -in "$dir/$name.pem" -noout -pubkey 2>/dev/null)" == \
     "$(openssl pkey -in "$dir/$name.key" -pubout 2>/dev/null)" ]] || return 1
  extensions "$name" "$kind" | cmp -s - "$dir/$name.ext"
}

made=()
if [[ ! -f "$dir/ca.pem" || ! -f "$dir/ca.key" ]] ||
   ! openssl x509 -in "$dir/ca.pem" -noout -checkend "$((86400 * 2))" >/dev/null 2>&1; then
  make_ca "$dir/ca" "kinemo CA"
  made+=(ca)
fi
for name in "${SERVICES[@]}"; do
  current "$name" server || { issue "$dir/ca" "$name" server "$dir/$name"; made+=("$name"); }
done
for name in "${CLIENTS[@]}"; do
  current "$name" client || { issue "$dir/ca" "$name" client "$dir/$name"; made+=("$name"); }
done

if [[ $extras == 1 ]]; then
  # A client certificate of the CA that expired long ago (openssl ca sets past dates).
  if ! { [[ -f "$dir/expired.pem" ]] && openssl verify -CAfile "$dir/ca.pem" -no_check_time "$dir/expired.pem" >/dev/null 2>&1; }; then
    mkdir -p "$tmp/db"
    : >"$tmp/db/index.txt"
    cat >"$tmp/ca.cnf" <<CNF
[ca]
default_ca = expired_ca
[expired_ca]
database = $tmp/db/index.txt
new_certs_dir = $tmp/db
serial = $tmp/db/serial
default_md = sha256
policy = anything
unique_subject = no
[anything]
organizationName = optional
commonName = supplied
[client]
basicConstraints = critical,CA:FALSE
keyUsage = critical,digitalSignature
extendedKeyUsage = clientAuth
subjectAltName = DNS:expired
CNF
    echo 1000 >"$tmp/db/serial"
    new_key "$tmp/expired.key"
    openssl req -new -key "$tmp/expired.key" -subj "/O=kinemo/CN=expired" -out "$tmp/expired.csr" 2>/dev/null
    openssl ca -batch -notext -config "$tmp/ca.cnf" -extensions client -cert "$dir/ca.pem" -keyfile "$dir/ca.key" \
      -startdate 20200101000000Z -enddate 20210101000000Z -in "$tmp/expired.csr" -out "$tmp/expired.pem" 2>/dev/null
    mv "$tmp/expired.key" "$dir/expired.key"
    mv "$tmp/expired.pem" "$dir/expired.pem"
    chmod 0644 "$dir/expired.pem"
    made+=(expired)
  fi
  # Another CA, and a client certificate it signed (a stranger to kinemo's CA).
  if [[ ! -f "$dir/other-ca.pem" || ! -f "$dir/other-ca.key" ]]; then
    make_ca "$dir/other-ca" "another CA"
    rm -f "$dir/stranger.pem"
    made+=(other-ca)
  fi
  if ! { [[ -f "$dir/stranger.pem" && -f "$dir/stranger.key" ]] &&
         openssl verify -CAfile "$dir/other-ca.pem" "$dir/stranger.pem" >/dev/null 2>&1; }; then
    issue "$dir/other-ca" stranger client "$dir/stranger"
    made+=(stranger)
  fi
fi
rm -f "$dir/ca.srl" "$dir/other-ca.srl"
if [[ ${#made[@]} -eq 0 ]]; then
  echo "certs: $dir is up to date"
else
  echo "certs: made ${made[*]} in $dir"
fi
