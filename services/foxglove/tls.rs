//! `wss://`: TLS in front of the relay's front door, for the `tls CERT.pem KEY.pem`
//! line (rustls with its `ring` backend, through tokio-rustls: pure Rust plus
//! ring's C, no system library).
//!
//! Each public port (`port`, and `sdk_port` when set) is a TLS listener: it
//! finishes the TLS handshake and hands the plain WebSocket bytes to the door
//! ([`relay`](super::relay)) on a loopback port of its own, so the door's token,
//! connection cap, subprotocol rename and message limits apply unchanged (the door
//! checks plain bytes and hands the plain socket to the SDK). TLS is terminated
//! here rather than in the SDK's server (`websocket-tls`) because the SDK is
//! reached only through the door, which must see the plain bytes.
//!
//! Bounds: a TLS handshake not finished within [`HANDSHAKE_TIMEOUT`] is closed; at
//! most `max_clients` handshakes are in progress at once (a new one closes the
//! oldest unfinished one, so strangers that never finish cannot lock a client
//! out); out of descriptors, the door's longest idle connection is closed and the
//! loop goes on; when either side of a connection ends, the other gets
//! [`CLOSE_GRACE`] to finish, then both close.

use std::{collections::VecDeque, net::SocketAddr, path::Path, sync::Arc, time::Duration};

use parking_lot::Mutex;
use tokio::{
    io::AsyncWriteExt,
    net::{TcpListener, TcpStream},
    sync::Notify,
};
use tokio_rustls::{
    TlsAcceptor,
    rustls::{
        self, ServerConfig,
        pki_types::{CertificateDer, PrivateKeyDer, pem::PemObject},
    },
};

use super::relay::Door;

/// How long a client may take to finish the TLS handshake.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(5);
/// How long one side of a connection may go on after the other ended.
const CLOSE_GRACE: Duration = Duration::from_secs(1);

/// The server's TLS settings from a PEM certificate chain and a PEM private key
/// (PKCS#8, PKCS#1 or SEC1), each read through the one checked open.
pub fn server_config(cert: &Path, key: &Path) -> Result<Arc<ServerConfig>, String> {
    let read = |p: &Path| {
        crate::files::read_limited(p, crate::files::MAX_TEXT_BYTES)
            .map_err(|e| format!("{}: {}", p.display(), e.reason()))
    };
    let chain: Vec<CertificateDer<'static>> = CertificateDer::pem_slice_iter(&read(cert)?)
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{}: not a PEM certificate ({e})", cert.display()))?;
    if chain.is_empty() {
        return Err(format!(
            "{}: no certificate in it (expected -----BEGIN CERTIFICATE-----)",
            cert.display()
        ));
    }
    let key_der = PrivateKeyDer::from_pem_slice(&read(key)?).map_err(|e| {
        format!(
            "{}: not a PEM private key ({e}; expected -----BEGIN PRIVATE KEY-----)",
            key.display()
        )
    })?;
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let config = ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| e.to_string())?
        .with_no_client_auth()
        .with_single_cert(chain, key_der)
        .map_err(|e| {
            format!(
                "{} and {}: the key does not go with the certificate, or is not one rustls \
                 takes ({e})",
                cert.display(),
                key.display()
            )
        })?;
    Ok(Arc::new(config))
}

/// The handshakes in progress, oldest first: each one's id and its kill switch.
#[derive(Default)]
struct Pending {
    list: Mutex<VecDeque<(u64, Arc<Notify>)>>,
    next: std::sync::atomic::AtomicU64,
}

impl Pending {
    /// Registers a handshake (closing the oldest when `max` are in progress).
    fn enter(&self, max: usize) -> (u64, Arc<Notify>) {
        let id = self.next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let kill = Arc::new(Notify::new());
        let mut list = self.list.lock();
        if list.len() >= max
            && let Some((_, oldest)) = list.pop_front()
        {
            oldest.notify_one();
        }
        list.push_back((id, kill.clone()));
        (id, kill)
    }

    fn leave(&self, id: u64) {
        self.list.lock().retain(|(i, _)| *i != id);
    }
}

/// Accepts TLS connections on `listener` for ever and hands each to the door
/// listening (plain) at `door_addr`.
pub async fn accept_loop(
    listener: TcpListener,
    acceptor: TlsAcceptor,
    door_addr: SocketAddr,
    door: Arc<Door>,
    max_pending: usize,
) {
    let pending = Arc::new(Pending::default());
    loop {
        let (tcp, peer) = match listener.accept().await {
            Ok(c) => c,
            Err(e) => {
                let fds = matches!(e.raw_os_error(), Some(libc::EMFILE | libc::ENFILE));
                if !(fds && door.evict_idle(&format!("accept failed ({e})"))) {
                    tracing::warn!("foxglove: accept (TLS) failed: {e}; trying again");
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
                continue;
            }
        };
        if door.refusals.holds(peer.ip()).is_some() {
            continue; // backed off for wrong tokens: not even a handshake
        }
        let (id, kill) = pending.enter(max_pending);
        let (acceptor, pending, door) = (acceptor.clone(), pending.clone(), door.clone());
        tokio::spawn(async move {
            let shake = tokio::time::timeout(HANDSHAKE_TIMEOUT, acceptor.accept(tcp));
            let r = tokio::select! {
                r = shake => r,
                () = kill.notified() => {
                    pending.leave(id);
                    tracing::info!("foxglove: client {peer}: closed its unfinished TLS handshake to admit a newer one");
                    return;
                }
            };
            pending.leave(id);
            let tls = match r {
                Ok(Ok(s)) => s,
                Ok(Err(e)) => {
                    tracing::info!("foxglove: client {peer}: TLS handshake failed: {e}");
                    return;
                }
                Err(_) => {
                    tracing::info!(
                        "foxglove: client {peer}: no TLS handshake within {HANDSHAKE_TIMEOUT:?}"
                    );
                    return;
                }
            };
            if let Err(e) = bridge(tls, peer, door_addr, &door).await {
                tracing::debug!("foxglove: client {peer} (TLS): {e}");
            }
        });
    }
}

/// Moves bytes between the client's TLS stream and a plain connection to the
/// door until one side ends (the other then gets [`CLOSE_GRACE`]).
async fn bridge(
    tls: tokio_rustls::server::TlsStream<TcpStream>,
    peer: SocketAddr,
    door_addr: SocketAddr,
    door: &Door,
) -> std::io::Result<()> {
    // Bound before it connects, so the door knows whom the port carries when
    // it accepts (`Door::bridge`).
    let sock = if door_addr.is_ipv4() {
        tokio::net::TcpSocket::new_v4()?
    } else {
        tokio::net::TcpSocket::new_v6()?
    };
    sock.bind(SocketAddr::new(door_addr.ip(), 0))?;
    let port = sock.local_addr()?.port();
    door.bridge(port, peer);
    let inner = sock.connect(door_addr).await;
    let r = match inner {
        Ok(inner) => carry(tls, inner).await,
        Err(e) => Err(e),
    };
    door.unbridge(port);
    r
}

async fn carry(
    tls: tokio_rustls::server::TlsStream<TcpStream>,
    inner: TcpStream,
) -> std::io::Result<()> {
    let _ = inner.set_nodelay(true);
    let (mut cr, mut cw) = tokio::io::split(tls);
    let (mut ir, mut iw) = inner.into_split();
    let up = async {
        let r = tokio::io::copy(&mut cr, &mut iw).await;
        let _ = iw.shutdown().await;
        r
    };
    let down = async {
        let r = tokio::io::copy(&mut ir, &mut cw).await;
        let _ = cw.shutdown().await;
        r
    };
    tokio::pin!(up, down);
    let first = tokio::select! {
        r = &mut up => { let _ = tokio::time::timeout(CLOSE_GRACE, &mut down).await; r }
        r = &mut down => { let _ = tokio::time::timeout(CLOSE_GRACE, &mut up).await; r }
    };
    first.map(|_| ())
}
