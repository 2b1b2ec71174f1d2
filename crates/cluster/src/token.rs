//! The cluster's shared token: what a client must show a worker that was
//! given one, in the `wisplight-token` metadata of every call.
//!
//! Without TLS it is the only thing that tells a coordinator (or a fellow
//! worker) from any client that reaches the port; with TLS it adds a
//! secret that a stray certificate of the same CA does not carry.

use tonic::metadata::AsciiMetadataValue;

use crate::ClusterError;

/// The metadata key of the token.
pub(crate) const TOKEN_KEY: &str = "wisplight-token";

/// The fewest characters a token may have.
pub const MIN_TOKEN_LEN: usize = 16;

/// A cluster token: at least [`MIN_TOKEN_LEN`] printable ASCII characters
/// without spaces (`openssl rand -hex 16` makes one). Its `Debug` does not
/// show it.
#[derive(Clone)]
pub struct Token(AsciiMetadataValue);

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(..)")
    }
}

impl Token {
    /// The token `text`, checked.
    pub fn new(text: &str) -> Result<Token, ClusterError> {
        let bad = |why: &str| ClusterError::Setup(format!("the cluster token {why}"));
        if text.len() < MIN_TOKEN_LEN {
            return Err(bad(&format!(
                "has {} characters: at least {MIN_TOKEN_LEN} (`openssl rand -hex 16` makes one)",
                text.len()
            )));
        }
        if !text.bytes().all(|b| b.is_ascii_graphic()) {
            return Err(bad("must be printable ASCII without spaces"));
        }
        text.parse()
            .map(Token)
            .map_err(|_| bad("is not a header value"))
    }

    pub(crate) fn value(&self) -> &AsciiMetadataValue {
        &self.0
    }
}

/// A worker's check of every call: with a token, calls that do not carry
/// it get UNAUTHENTICATED (compared in constant time); without, all pass.
#[derive(Debug, Clone)]
pub(crate) struct RequireToken(pub(crate) Option<Token>);

impl tonic::service::Interceptor for RequireToken {
    fn call(&mut self, req: tonic::Request<()>) -> Result<tonic::Request<()>, tonic::Status> {
        let Some(token) = &self.0 else {
            return Ok(req);
        };
        match req.metadata().get(TOKEN_KEY) {
            Some(v) if constant_time_eq::constant_time_eq(v.as_bytes(), token.0.as_bytes()) => {
                Ok(req)
            }
            Some(_) => Err(tonic::Status::unauthenticated(
                "this worker's cluster token is another (--token or WISPLIGHT_TOKEN)",
            )),
            None => Err(tonic::Status::unauthenticated(
                "this worker requires the cluster's token: give the coordinator the same \
                 --token (or WISPLIGHT_TOKEN) as its workers",
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tonic::service::Interceptor;

    fn call(check: &mut RequireToken, token: Option<&str>) -> Result<(), tonic::Code> {
        let mut req = tonic::Request::new(());
        if let Some(t) = token {
            req.metadata_mut().insert(TOKEN_KEY, t.parse().unwrap());
        }
        check.call(req).map(|_| ()).map_err(|s| s.code())
    }

    #[test]
    fn a_worker_with_a_token_lets_through_only_calls_that_carry_it() {
        let mut check = RequireToken(Some(Token::new("0123456789abcdef").unwrap()));
        assert_eq!(call(&mut check, Some("0123456789abcdef")), Ok(()));
        assert_eq!(
            call(&mut check, Some("0123456789abcdeF")),
            Err(tonic::Code::Unauthenticated)
        );
        assert_eq!(
            call(&mut check, Some("0123456789abcdef0")),
            Err(tonic::Code::Unauthenticated)
        );
        assert_eq!(call(&mut check, None), Err(tonic::Code::Unauthenticated));
        let mut open = RequireToken(None);
        assert_eq!(call(&mut open, None), Ok(()));
        assert_eq!(call(&mut open, Some("anything")), Ok(()));
    }

    #[test]
    fn short_or_unprintable_tokens_are_refused_by_what_is_wrong() {
        let e = Token::new("short").unwrap_err().to_string();
        assert!(e.contains("at least 16"), "{e}");
        let e = Token::new("0123456789 abcdef").unwrap_err().to_string();
        assert!(e.contains("printable"), "{e}");
        assert_eq!(
            format!("{:?}", Token::new("0123456789abcdef").unwrap()),
            "Token(..)"
        );
    }
}
