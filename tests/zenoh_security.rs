//! `[zenoh]` security enforced, not only configured: a bridge on a TLS endpoint with mutual
//! TLS (`[zenoh.tls] enable_mtls = true`) and Zenoh access control from its `zenoh_config`
//! file. Certificates are made for the test with the `openssl` tool (tests/install-deps).
//!
//! - a client with a certificate of the machine's CA is served (task list, an operation),
//!   and so is a hytask session whose `[zenoh.tls]` names its client certificate;
//! - a client whose certificate the access control denies (`viewer`) still reads the task
//!   list but its operation call is dropped: no reply at all;
//! - a client without a certificate, one with a certificate of another CA, and one in plain
//!   TCP never reach the bridge.
//!
//! Every wait is a hang guard. A refusal is checked as "no reply", once the same query was
//! answered for an allowed client over the same route: it holds for any interleaving.
#![allow(clippy::unwrap_used)]

#[path = "zenoh/peer_rig.rs"]
mod peer_rig;
mod zenoh_support;

use hytask::bridge::remote_host::PeerHost;
use hytask::config::ZenohConfig;
use hytask::rt::prelude::*;
use peer_rig::{Worker, SCHED};
use serde_json::json;
use std::path::Path;
use std::process::Command;
use std::time::Duration;
use zenoh::Wait;
use zenoh_support::{client_config, free_port, query};

const GUARD: Duration = Duration::from_secs(60);
/// How long a refused query is given to (wrongly) get a reply.
const REFUSED_WAIT: Duration = Duration::from_secs(10);

fn openssl(dir: &Path, args: &[&str]) {
    let out = Command::new("openssl")
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap_or_else(|e| panic!("openssl missing ({e}): run tests/install-deps"));
    assert!(
        out.status.success(),
        "openssl {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `openssl req` with a new P-256 key in `key`, common name `cn`, written to `out`, plus
/// `extra` arguments (`-x509 …` for a self-signed certificate, none for a signing request).
fn ec_request(dir: &Path, key: &str, out: &str, cn: &str, extra: &[&str]) {
    let subj = format!("/CN={cn}");
    let mut args = vec![
        "req",
        "-newkey",
        "ec",
        "-pkeyopt",
        "ec_paramgen_curve:prime256v1",
        "-nodes",
        "-keyout",
        key,
        "-out",
        out,
        "-subj",
        &subj,
    ];
    args.extend_from_slice(extra);
    openssl(dir, &args);
}

/// `<ca>.pem` / `<ca>.key`: a CA.
fn make_ca(dir: &Path, ca: &str) {
    let (pem, key) = (format!("{ca}.pem"), format!("{ca}.key"));
    ec_request(
        dir,
        &key,
        &pem,
        ca,
        &[
            "-x509",
            "-days",
            "2",
            "-addext",
            "basicConstraints=critical,CA:TRUE",
            "-addext",
            "keyUsage=critical,keyCertSign,cRLSign",
        ],
    );
}

/// `<name>.pem` / `<name>.key`: a certificate with common name `name` signed by `ca`,
/// valid for 127.0.0.1 and localhost, as server and client.
fn make_cert(dir: &Path, ca: &str, name: &str) {
    let ext = format!("{name}.ext");
    std::fs::write(
        dir.join(&ext),
        "subjectAltName=DNS:localhost,IP:127.0.0.1\nbasicConstraints=CA:FALSE\n\
         keyUsage=digitalSignature\nextendedKeyUsage=serverAuth,clientAuth\n",
    )
    .unwrap();
    let (key, csr, pem) = (
        format!("{name}.key"),
        format!("{name}.csr"),
        format!("{name}.pem"),
    );
    ec_request(dir, &key, &csr, name, &[]);
    openssl(
        dir,
        &[
            "x509",
            "-req",
            "-in",
            &csr,
            "-CA",
            &format!("{ca}.pem"),
            "-CAkey",
            &format!("{ca}.key"),
            "-CAcreateserial",
            "-out",
            &pem,
            "-days",
            "2",
            "-extfile",
            &ext,
        ],
    );
}

/// Zenoh access control: callers with certificate `viewer` may not query operations or
/// control methods; everything else is allowed.
const ACL: &str = r#"{
  access_control: {
    enabled: true,
    default_permission: "allow",
    rules: [{
      id: "no-commands",
      permission: "deny",
      flows: ["ingress"],
      messages: ["query"],
      key_exprs: ["hytask/sec/*/op/**", "hytask/sec/control/**"],
    }],
    subjects: [{ id: "viewers", cert_common_names: ["viewer"] }],
    policies: [{ rules: ["no-commands"], subjects: ["viewers"] }],
  },
}"#;

/// A client session on `endpoint` trusting `ca`, presenting `cert` if given: `None` when
/// Zenoh refuses to open it (the link could not be made).
fn tls_client(dir: &Path, endpoint: &str, ca: &str, cert: Option<&str>) -> Option<zenoh::Session> {
    let p = |f: String| json!(dir.join(f).display().to_string()).to_string();
    let mut c = client_config(endpoint);
    c.insert_json5(
        "transport/link/tls/root_ca_certificate",
        &p(format!("{ca}.pem")),
    )
    .unwrap();
    if let Some(name) = cert {
        c.insert_json5("transport/link/tls/enable_mtls", "true")
            .unwrap();
        c.insert_json5(
            "transport/link/tls/connect_certificate",
            &p(format!("{name}.pem")),
        )
        .unwrap();
        c.insert_json5(
            "transport/link/tls/connect_private_key",
            &p(format!("{name}.key")),
        )
        .unwrap();
    }
    zenoh::open(c).wait().ok()
}

/// No reply to `key` within [`REFUSED_WAIT`].
fn refused(s: &zenoh::Session, key: &str, payload: Option<&serde_json::Value>) -> bool {
    let mut q = s.get(key).timeout(REFUSED_WAIT);
    if let Some(p) = payload {
        q = q.payload(p.to_string());
    }
    q.wait().unwrap().recv().is_err()
}

#[test]
fn tls_and_access_control_from_the_config_are_enforced() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    make_ca(dir, "ca");
    make_ca(dir, "rogue");
    for name in ["mill", "operator", "viewer"] {
        make_cert(dir, "ca", name);
    }
    make_cert(dir, "rogue", "intruder");
    std::fs::write(dir.join("acl.json5"), ACL).unwrap();
    let port = free_port();
    let endpoint = format!("tls/127.0.0.1:{port}");
    let f = |n: &str| dir.join(n).display().to_string();
    let cfg: ZenohConfig = toml::from_str(&format!(
        "listen = [{endpoint:?}]\nzenoh_config = {:?}\n\n[tls]\nroot_ca_certificate = {:?}\n\
         listen_certificate = {:?}\nlisten_private_key = {:?}\nenable_mtls = true\n",
        f("acl.json5"),
        f("ca.pem"),
        f("mill.pem"),
        f("mill.key"),
    ))
    .unwrap();

    let mut app = Deployment::new();
    app.add_periodic("worker", Worker::default(), SCHED)
        .unwrap();
    app.configure().unwrap();
    let session = hytask::bridge::session::open(&cfg).unwrap();
    let peer = PeerHost::serve(session, app.start().unwrap(), "sec", &cfg).unwrap();
    let work = json!({"ms": 1});

    // Certified by the machine's CA, allowed by the access control: served.
    let op = tls_client(dir, &endpoint, "ca", Some("operator")).expect("the operator's link");
    assert!(query(&op, "hytask/sec/tasks", None, GUARD).is_ok());
    let r = query(&op, "hytask/sec/worker/op/work", Some(&work), GUARD).unwrap();
    assert_eq!(r["status"], "done", "{r}");

    // Another hytask process (as `hytask peer` or `hytask serve` with `[[remote]]`) whose
    // `[zenoh.tls]` names its client certificate reaches the machine and checks its tasks.
    let remote: ZenohConfig = toml::from_str(&format!(
        "listen = []\nconnect = [{endpoint:?}]\n\n[tls]\nroot_ca_certificate = {:?}\n\
         connect_certificate = {:?}\nconnect_private_key = {:?}\nenable_mtls = true\n",
        f("ca.pem"),
        f("operator.pem"),
        f("operator.key"),
    ))
    .unwrap();
    let s = hytask::bridge::session::open(&remote).unwrap();
    let rc = hytask::config::remote::RemoteConfig {
        name: "sec".into(),
        machine: None,
        timeout_s: GUARD.as_secs_f64(),
        critical: false,
        check: true,
    };
    let link = hytask::bridge::remote::RemoteLink::connect(&s, &rc).unwrap();
    link.require("worker", &["work"], &[], &[]).unwrap();
    drop(link);
    let _ = s.close().wait();

    // No certificate, another CA's certificate, plain TCP: no session, or one that never
    // reaches the bridge.
    let intruders = [
        ("no certificate", tls_client(dir, &endpoint, "ca", None)),
        (
            "another CA's certificate",
            tls_client(dir, &endpoint, "rogue", Some("intruder")),
        ),
    ];
    for (what, s) in intruders {
        if let Some(s) = s {
            assert!(
                refused(&s, "hytask/sec/tasks", None),
                "a client with {what} was served"
            );
        }
    }
    let mut plain = zenoh::Config::default();
    plain.insert_json5("mode", "\"client\"").unwrap();
    plain
        .insert_json5(
            "connect/endpoints",
            &json!([format!("tcp/127.0.0.1:{port}")]).to_string(),
        )
        .unwrap();
    plain
        .insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    if let Ok(s) = zenoh::open(plain).wait() {
        assert!(
            refused(&s, "hytask/sec/tasks", None),
            "plain TCP was served"
        );
    }
    // Certified, but denied commands by the access control: reads, no operation.
    let viewer = tls_client(dir, &endpoint, "ca", Some("viewer")).expect("the viewer's link");
    assert!(query(&viewer, "hytask/sec/tasks", None, GUARD).is_ok());
    assert!(
        refused(&viewer, "hytask/sec/worker/op/work", Some(&work)),
        "the access control let the viewer's operation through"
    );
    assert!(refused(&viewer, "hytask/sec/control/call", None));

    peer.stop();
}
