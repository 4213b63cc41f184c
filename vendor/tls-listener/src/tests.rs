//! jderobot patch: tests of the accept loop with a scripted listener and a mock
//! TLS whose handshake is one byte from the client.

use super::*;
use std::collections::VecDeque;
use std::io;
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};

/// A handshake that finishes when the client sends one byte.
#[derive(Clone)]
struct OneByte;

impl AsyncTls<DuplexStream> for OneByte {
    type Stream = DuplexStream;
    type Error = io::Error;
    type AcceptFuture = Pin<Box<dyn Future<Output = io::Result<DuplexStream>> + Send>>;

    fn accept(&self, mut conn: DuplexStream) -> Self::AcceptFuture {
        Box::pin(async move {
            conn.read_exact(&mut [0]).await?;
            Ok(conn)
        })
    }
}

/// Hands out its connections in order, then fails with EMFILE at every call
/// (`fail`) or stays pending.
struct Script {
    conns: VecDeque<DuplexStream>,
    fail: bool,
}

impl AsyncAccept for Script {
    type Connection = DuplexStream;
    type Address = ();
    type Error = io::Error;

    fn poll_accept(
        self: Pin<&mut Self>,
        _cx: &mut Context<'_>,
    ) -> Poll<Result<(DuplexStream, ()), io::Error>> {
        let this = self.get_mut();
        match this.conns.pop_front() {
            Some(c) => Poll::Ready(Ok((c, ()))),
            None if this.fail => Poll::Ready(Err(io::Error::from_raw_os_error(24))),
            None => Poll::Pending,
        }
    }
}

/// `n` connections: the listener's ends and the clients' ends.
fn pairs(n: usize) -> (VecDeque<DuplexStream>, Vec<DuplexStream>) {
    (0..n).map(|_| tokio::io::duplex(64)).unzip()
}

/// Whether the server closed the client's connection (EOF at once).
async fn closed(client: &mut DuplexStream) -> bool {
    let mut byte = [0];
    let read = timeout(Duration::from_millis(20), client.read(&mut byte));
    matches!(read.await, Ok(Ok(0)))
}

#[tokio::test]
async fn handshakes_time_out_while_accepting_fails() {
    let (conns, mut clients) = pairs(1);
    let mut listener = builder(OneByte)
        .handshake_timeout(Duration::from_millis(50))
        .listen(Script { conns, fail: true });
    // A caller that retries after each error, as zenoh-link-tls does.
    let mut timed_out = false;
    for _ in 0..50 {
        match listener.accept().await {
            Err(Error::HandshakeTimeout { .. }) => {
                timed_out = true;
                break;
            }
            Err(Error::ListenerError(_)) => tokio::time::sleep(Duration::from_millis(10)).await,
            other => panic!("unexpected {:?}", other.map(|_| ())),
        }
    }
    assert!(timed_out, "the silent client's handshake never timed out");
    assert!(
        closed(&mut clients[0]).await,
        "its connection is still open"
    );
}

#[tokio::test]
async fn a_new_connection_over_the_cap_closes_the_oldest_handshake() {
    let (conns, mut clients) = pairs(4);
    let mut listener = builder(OneByte)
        .max_handshakes(NonZeroUsize::new(2).unwrap())
        .listen(Script { conns, fail: false });
    // All four are accepted; none has finished its handshake.
    let idle = timeout(Duration::from_millis(50), listener.accept()).await;
    assert!(idle.is_err(), "a handshake finished");
    for (i, c) in clients.iter_mut().enumerate() {
        assert_eq!(closed(c).await, i < 2, "client {i}");
    }
    // The newest finishes its handshake and is returned, and no closed one is.
    clients[3].write_all(&[1]).await.unwrap();
    let got = timeout(Duration::from_secs(1), listener.accept()).await;
    assert!(
        matches!(got, Ok(Ok(_))),
        "the newest client was not admitted"
    );
}
