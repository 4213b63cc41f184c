//! Facades for TLS support when the "websocket-tls" feature is disabled.

use crate::{
    FoxgloveError,
    websocket::streams::{Acceptor, ServerStream, TlsIdentity},
};
use tokio_util::either::Either;

/// jderobot patch: a stream handed to the server
/// ([`crate::WebSocketServerHandle::serve_stream`]): any async byte stream.
pub trait HandedStream:
    tokio::io::AsyncRead + tokio::io::AsyncWrite + Send + Sync + Unpin + 'static
{
}
impl<T: tokio::io::AsyncRead + tokio::io::AsyncWrite + Send + Sync + Unpin + 'static> HandedStream
    for T
{
}

pub struct StreamConfiguration {}

impl StreamConfiguration {
    /// Returns an error if a TlsIdentity is provided.
    pub fn new(identity: Option<&TlsIdentity>) -> Result<Self, FoxgloveError> {
        if identity.is_some() {
            return Err(FoxgloveError::ConfigurationError(
                "TLS is not enabled".to_string(),
            ));
        }

        Ok(Self {})
    }
}

impl Acceptor for StreamConfiguration {
    /// Always returns a plain stream.
    async fn accept(
        &self,
        stream: tokio::net::TcpStream,
    ) -> Result<ServerStream<tokio::net::TcpStream>, crate::FoxgloveError> {
        Ok(Either::Left(stream))
    }

    fn accepts_tls(&self) -> bool {
        false
    }
}
