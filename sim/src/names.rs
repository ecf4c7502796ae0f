//! Names of things as a person reads them in messages (never Rust `Debug` output). Requests,
//! replies and refusal reasons are named by the protocol itself (`Request::name`,
//! `Reply::name`, `NackCode` Display); this module names what the protocol does not.

/// Tooth counts as the command line takes them: `49,51,50,50`.
pub fn teeth(z: &[u32; 4]) -> String {
    z.map(|v| v.to_string()).join(",")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn teeth_read_as_typed() {
        assert_eq!(teeth(&[49, 51, 50, 50]), "49,51,50,50");
    }
}
