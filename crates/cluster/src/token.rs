//! The cluster's shared token, and the proofs of knowing it.
//!
//! The token never crosses the wire. A coordinator proves it in its
//! Hello, over a nonce the worker gave (`Challenge`) and one of its own,
//! and the worker proves it back over the coordinator's nonce and the
//! session it opened; a worker proves it to a fellow worker (`Prove`)
//! over that worker's nonce before the fellow sends it anything. Each
//! proof is HMAC-SHA-256 (RFC 2104) of a message that names its purpose,
//! so that a proof of one kind never passes for another. Every later
//! call names its session (128 random bits), which only the coordinator
//! and its workers learn.
//!
//! Without TLS the token is the only thing that tells a coordinator (or a
//! fellow worker) from any client that reaches the port; with TLS it adds
//! a secret that a stray certificate of the same CA does not carry.

use ring::hmac;

use crate::ClusterError;

/// The fewest characters a token may have.
pub const MIN_TOKEN_LEN: usize = 16;

/// Bytes of every nonce this side makes.
pub(crate) const NONCE_BYTES: usize = 16;

/// The most bytes of a nonce a caller may send to be proved over.
pub(crate) const MAX_NONCE_BYTES: usize = 64;

/// A cluster token: at least [`MIN_TOKEN_LEN`] printable ASCII characters
/// without spaces (`openssl rand -hex 16` makes one). Its `Debug` does not
/// show it.
#[derive(Clone)]
pub struct Token(String);

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
        Ok(Token(text.to_string()))
    }

    /// The key its proofs are made with.
    pub(crate) fn key(&self) -> &[u8] {
        self.0.as_bytes()
    }
}

/// What a proof is for: part of the message proved, so that a proof of
/// one kind never passes for another.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Purpose {
    /// A coordinator's Hello: over the worker's challenge and its own
    /// nonce.
    Hello,
    /// A worker's Hello reply: over the coordinator's nonce and the
    /// session opened.
    Worker,
    /// A worker to a fellow worker: over the fellow's nonce and the
    /// session named.
    Peer,
}

impl Purpose {
    fn label(self) -> &'static [u8] {
        match self {
            Purpose::Hello => b"wisplight hello",
            Purpose::Worker => b"wisplight worker",
            Purpose::Peer => b"wisplight peer",
        }
    }
}

/// The message proved: the purpose's label and each part, every one
/// preceded by its length (4 bytes, big-endian), so that no two lists of
/// parts make the same message.
fn message(purpose: Purpose, parts: &[&[u8]]) -> Vec<u8> {
    let mut m = Vec::new();
    for p in std::iter::once(purpose.label()).chain(parts.iter().copied()) {
        m.extend_from_slice(&(p.len() as u32).to_be_bytes());
        m.extend_from_slice(p);
    }
    m
}

/// The proof, with `key`, of `parts` for `purpose`: HMAC-SHA-256.
pub(crate) fn prove(key: &[u8], purpose: Purpose, parts: &[&[u8]]) -> Vec<u8> {
    let k = hmac::Key::new(hmac::HMAC_SHA256, key);
    hmac::sign(&k, &message(purpose, parts)).as_ref().to_vec()
}

/// Whether `proof` is the proof of `parts` for `purpose` with `key`
/// (compared in constant time).
pub(crate) fn proves(key: &[u8], purpose: Purpose, parts: &[&[u8]], proof: &[u8]) -> bool {
    let k = hmac::Key::new(hmac::HMAC_SHA256, key);
    hmac::verify(&k, &message(purpose, parts), proof).is_ok()
}

/// A fresh random nonce.
pub(crate) fn nonce() -> Result<[u8; NONCE_BYTES], getrandom::Error> {
    let mut b = [0u8; NONCE_BYTES];
    getrandom::fill(&mut b)?;
    Ok(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_proof_passes_only_for_its_key_purpose_and_parts() {
        let key = b"0123456789abcdef";
        let p = prove(key, Purpose::Peer, &[b"nonce", b"session"]);
        assert_eq!(p.len(), 32);
        assert!(proves(key, Purpose::Peer, &[b"nonce", b"session"], &p));
        assert!(!proves(
            b"0123456789abcdeF",
            Purpose::Peer,
            &[b"nonce", b"session"],
            &p
        ));
        assert!(!proves(key, Purpose::Hello, &[b"nonce", b"session"], &p));
        assert!(!proves(key, Purpose::Peer, &[b"nonce", b"sessioN"], &p));
        // Parts are framed: moving a byte from one to the next is another
        // message.
        assert!(!proves(key, Purpose::Peer, &[b"nonces", b"ession"], &p));
        assert!(!proves(
            key,
            Purpose::Peer,
            &[b"nonce", b"session"],
            &p[..31]
        ));
        assert!(!proves(key, Purpose::Peer, &[b"nonce", b"session"], &[]));
    }

    #[test]
    fn the_proof_is_rfc_4231_hmac_sha_256() {
        // RFC 4231, test case 2: key "Jefe", data "what do ya want for
        // nothing?". Our message frames its parts, so the check goes
        // through ring directly with the framed message rebuilt by hand.
        let k = hmac::Key::new(hmac::HMAC_SHA256, b"Jefe");
        let tag = hmac::sign(&k, b"what do ya want for nothing?");
        let hex: String = tag.as_ref().iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(
            hex,
            "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"
        );
        // The framing: label and parts, each with its length.
        let m = message(Purpose::Hello, &[b"ab", b""]);
        let mut want = Vec::new();
        want.extend_from_slice(&15u32.to_be_bytes());
        want.extend_from_slice(b"wisplight hello");
        want.extend_from_slice(&2u32.to_be_bytes());
        want.extend_from_slice(b"ab");
        want.extend_from_slice(&0u32.to_be_bytes());
        assert_eq!(m, want);
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
