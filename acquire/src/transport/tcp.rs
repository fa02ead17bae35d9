//! Raw TCP sockets (LXI "SCPI-raw", port 5025 by default): an instrument's SCPI session over the
//! network, opened with a connect timeout and `TCP_NODELAY` (every command is one short line).

use std::time::Duration;

use tokio::net::TcpStream;

use super::TransportError;

/// The IANA/LXI port of a raw SCPI socket.
pub const SCPI_RAW_PORT: u16 = 5025;

/// Where a raw SCPI socket is: host name or address and port.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct SocketAddress {
    /// Host name or IP address.
    pub host: String,
    /// TCP port.
    pub port: u16,
}

impl SocketAddress {
    /// Parses `host`, `host:port` or `[v6]:port`; the port defaults to [`SCPI_RAW_PORT`].
    /// `None` when the host is empty or the port is not a number in 1..=65535.
    pub fn parse(text: &str) -> Option<SocketAddress> {
        let text = text.trim();
        let (host, port) = if let Some(rest) = text.strip_prefix('[') {
            let (h, tail) = rest.split_once(']')?;
            match tail.strip_prefix(':') {
                Some(p) => (h, Some(p)),
                None if tail.is_empty() => (h, None),
                None => return None,
            }
        } else {
            match text.rsplit_once(':') {
                Some((h, p)) if !h.contains(':') => (h, Some(p)),
                _ => (text, None),
            }
        };
        let port = match port {
            Some(p) => p.parse::<u16>().ok().filter(|p| *p > 0)?,
            None => SCPI_RAW_PORT,
        };
        if host.is_empty() {
            return None;
        }
        Some(SocketAddress {
            host: host.to_string(),
            port,
        })
    }
}

impl std::fmt::Display for SocketAddress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.host.contains(':') {
            write!(f, "tcp:[{}]:{}", self.host, self.port)
        } else {
            write!(f, "tcp:{}:{}", self.host, self.port)
        }
    }
}

/// An open raw SCPI socket.
pub struct TcpTransport {
    name: String,
    inner: TcpStream,
}

impl std::fmt::Debug for TcpTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TcpTransport")
            .field("port", &self.name)
            .finish()
    }
}

/// Connects to `address` within `timeout`. Must be called inside a tokio runtime.
pub async fn connect_tcp(
    address: &SocketAddress,
    timeout: Duration,
) -> Result<TcpTransport, TransportError> {
    let name = address.to_string();
    let target = (address.host.as_str(), address.port);
    let stream = match tokio::time::timeout(timeout, TcpStream::connect(target)).await {
        Err(_) => {
            return Err(TransportError::Socket {
                port: name,
                detail: format!("no connection within {timeout:?}"),
            })
        }
        Ok(Err(e)) => {
            return Err(TransportError::Socket {
                port: name,
                detail: e.to_string(),
            })
        }
        Ok(Ok(s)) => s,
    };
    // Each SCPI command is one short line: send it now rather than after Nagle's delay.
    stream
        .set_nodelay(true)
        .map_err(|e| TransportError::Socket {
            port: name.clone(),
            detail: e.to_string(),
        })?;
    Ok(TcpTransport {
        name,
        inner: stream,
    })
}

impl TcpTransport {
    /// Wraps an accepted or connected stream (the simulated instrument's side), named `name`.
    pub fn from_stream(name: &str, inner: TcpStream) -> TcpTransport {
        TcpTransport {
            name: name.to_string(),
            inner,
        }
    }
}

stream_transport!(TcpTransport);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_default_to_the_scpi_raw_port() {
        let a = SocketAddress::parse("192.168.1.20").unwrap();
        assert_eq!((a.host.as_str(), a.port), ("192.168.1.20", 5025));
        let a = SocketAddress::parse("gen.lab:5555").unwrap();
        assert_eq!((a.host.as_str(), a.port), ("gen.lab", 5555));
        let a = SocketAddress::parse("[::1]:6000").unwrap();
        assert_eq!((a.host.as_str(), a.port), ("::1", 6000));
        assert_eq!(a.to_string(), "tcp:[::1]:6000");
        assert!(SocketAddress::parse("").is_none());
        assert!(SocketAddress::parse("host:0").is_none());
        assert!(SocketAddress::parse("host:http").is_none());
        assert!(SocketAddress::parse(":5025").is_none());
    }

    #[tokio::test]
    async fn a_refused_connection_names_the_address() {
        // Bind then drop a listener: its port is then (almost certainly) closed.
        let l = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let port = l.local_addr().unwrap().port();
        drop(l);
        let a = SocketAddress {
            host: "127.0.0.1".into(),
            port,
        };
        let e = connect_tcp(&a, Duration::from_secs(2)).await.unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains(&format!("tcp:127.0.0.1:{port}")), "{msg}");
    }
}
