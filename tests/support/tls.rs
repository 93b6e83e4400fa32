//! A TLS terminator in front of a test server, as a deployment puts one (a load balancer, a
//! reverse proxy): `https://localhost:PORT` with the certificate of `tests/data/tls/`, signed by
//! the test CA there, each connection's bytes passed on to the server and back.

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use rustls::{ServerConfig, ServerConnection};
use std::io::{Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

fn data(file: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/data/tls")
        .join(file)
}

/// The test CA's certificate, which signed `localhost`'s: what a client is told to trust.
pub fn ca_file() -> String {
    data("ca.pem").display().to_string()
}

/// The key of `localhost`'s certificate: a PEM file with no certificate in it.
pub fn key_file() -> String {
    data("localhost.key").display().to_string()
}

/// `https://localhost:PORT`, terminating TLS for the plain HTTP server at `base`
/// (`http://127.0.0.1:PORT`) for as long as the test binary runs.
pub fn terminate(base: &str) -> String {
    let backend = base.trim_start_matches("http://").to_owned();
    let certificates = CertificateDer::pem_file_iter(data("localhost.pem"))
        .unwrap()
        .collect::<Result<Vec<_>, _>>()
        .unwrap();
    let key = PrivateKeyDer::from_pem_file(data("localhost.key")).unwrap();
    // ring's, as ureq's client side uses (rustls deprecates it for lacking post-quantum key
    // exchange; aws-lc-rs would compile far longer, and a test needs none).
    #[allow(deprecated)]
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let config = ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .unwrap()
        .with_no_client_auth()
        .with_single_cert(certificates, key)
        .unwrap();
    let config = Arc::new(config);
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    std::thread::spawn(move || {
        for client in listener.incoming().flatten() {
            let (config, backend) = (config.clone(), backend.clone());
            std::thread::spawn(move || {
                if let Ok(server) = TcpStream::connect(&backend) {
                    pass_on(client, server, config);
                }
            });
        }
    });
    format!("https://localhost:{port}")
}

/// One connection: what the client sends, decrypted, to the server on one thread; the server's
/// answer, encrypted, back on this one. The TLS state is shared under a lock, which neither
/// holds while it waits for bytes.
fn pass_on(client: TcpStream, server: TcpStream, config: Arc<ServerConfig>) {
    let tls = Arc::new(Mutex::new(ServerConnection::new(config).unwrap()));
    let (mut from_client, mut to_server) =
        (client.try_clone().unwrap(), server.try_clone().unwrap());
    let mut to_client = client.try_clone().unwrap();
    let inbound = {
        let tls = tls.clone();
        std::thread::spawn(move || {
            let mut buffer = [0u8; 16 * 1024];
            while let Ok(read @ 1..) = from_client.read(&mut buffer) {
                let mut plain = Vec::new();
                {
                    let mut tls = tls.lock().unwrap();
                    let mut bytes = &buffer[..read];
                    while !bytes.is_empty() {
                        if tls.read_tls(&mut bytes).is_err() || tls.process_new_packets().is_err() {
                            let _ = tls.write_tls(&mut to_client);
                            return;
                        }
                    }
                    let _ = tls.reader().read_to_end(&mut plain);
                    while tls.wants_write() && tls.write_tls(&mut to_client).is_ok() {}
                }
                if to_server.write_all(&plain).is_err() {
                    break;
                }
            }
            let _ = to_server.shutdown(Shutdown::Write);
        })
    };
    let (mut from_server, mut to_client) = (server, client);
    let mut buffer = [0u8; 16 * 1024];
    while let Ok(read @ 1..) = from_server.read(&mut buffer) {
        let mut tls = tls.lock().unwrap();
        if tls.writer().write_all(&buffer[..read]).is_err() {
            break;
        }
        while tls.wants_write() && tls.write_tls(&mut to_client).is_ok() {}
    }
    {
        let mut tls = tls.lock().unwrap();
        tls.send_close_notify();
        while tls.wants_write() && tls.write_tls(&mut to_client).is_ok() {}
    }
    let _ = to_client.shutdown(Shutdown::Both);
    let _ = inbound.join();
}
