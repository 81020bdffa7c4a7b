//! The control plane's protocol: what a sequencer asks the manager and what it gets back, and
//! the events the manager pushes. Encoded with postcard, one entry point each way, with a
//! version check (a client of another protocol version gets a precise error, not garbage).
//!
//! Transport (see [`crate::names`]): requests and responses travel over the iceoryx2
//! request-response service `skillfab/control` as byte slices; a client wakes the manager
//! through `skillfab/manager/wake` and is woken through `skillfab/client/<id>`. Events are
//! published on `skillfab/events` (byte slices, paired event service of the same name).

mod client_to_manager;
mod events;
mod manager_to_client;
mod plan;

pub use client_to_manager::*;
pub use events::*;
pub use manager_to_client::*;
pub use plan::*;

use crate::schema::MessageSchema;

/// Version of this protocol; bumped on any incompatible change.
pub const PROTOCOL_VERSION: u16 = 6;

/// The declared type names of a skill's schema, for lists.
pub fn type_name(schema: &MessageSchema) -> String {
    schema.type_name.clone()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::value::Value;

    #[test]
    fn a_large_monitor_firing_is_cut_to_fit_and_small_events_are_untouched() {
        let fired = |values: Vec<(String, Value)>| Event {
            seq: 7,
            cycle: 9,
            time_ns: 11,
            kind: EventKind::MonitorFired {
                id: 3,
                client: "1-0".into(),
                expr: "max(cam.image.data) > 250 and denning.link.fresh".into(),
                values,
                stamp_ns: 5,
            },
        };
        let small = fired(vec![("denning.link.fresh".into(), Value::Bool(true))]);
        assert_eq!(
            encode_event_within(&small, 2048),
            Some(encode_event(&small).unwrap())
        );
        let image = Value::Array((0..100_000).map(|i| Value::UInt(i % 256)).collect());
        let big = fired(vec![
            ("cam.image.data".into(), image),
            ("denning.link.fresh".into(), Value::Bool(true)),
        ]);
        let b = encode_event_within(&big, 2048).unwrap();
        assert!(b.len() <= 2048, "{}", b.len());
        let e = decode_event(&b).unwrap();
        assert_eq!((e.seq, e.cycle), (7, 9));
        let EventKind::MonitorFired { id, values, .. } = e.kind else {
            panic!("{e:?}")
        };
        assert_eq!(id, 3);
        assert_eq!(values[1], ("denning.link.fresh".into(), Value::Bool(true)));
        let Value::Array(kept) = &values[0].1 else {
            panic!("{values:?}")
        };
        assert!(kept.len() > 10, "as much as fits is kept: {}", kept.len());
        assert_eq!(kept[0], Value::UInt(0));
        let Some(Value::Text(more)) = kept.last() else {
            panic!("{kept:?}")
        };
        assert_eq!(*more, format!("… {} more", 100_000 - (kept.len() - 1)));
        // Nothing fits a tiny budget but the id: no event rather than a broken one.
        assert_eq!(encode_event_within(&big, 16), None);
    }

    #[test]
    fn requests_round_trip_and_versions_are_checked() {
        let r = Request::SetParam {
            skill: "scale".into(),
            param: "gain".into(),
            value: ParamArg::Text("3".into()),
        };
        let b = encode_request("12-1", 7, &r).unwrap();
        assert_eq!(decode_request(&b).unwrap().request, r);
        let mut other = b.clone();
        other[0] = 9; // a varint 9: another protocol version
        assert!(matches!(
            decode_request(&other),
            Err(ControlError::Version { client: 9, .. })
        ));
        assert!(matches!(
            decode_request(&b[..3]),
            Err(ControlError::Malformed(_))
        ));
        assert!(matches!(
            decode_request(&[]),
            Err(ControlError::Malformed(_))
        ));
    }

    proptest::proptest! {
        #[test]
        fn any_bytes_decode_or_error_without_panicking(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..256)) {
            let _ = decode_request(&bytes);
            let _ = decode_response(&bytes);
            let _ = decode_event(&bytes);
        }

        #[test]
        fn set_param_requests_round_trip(skill in "[a-z]{1,12}", param in "[a-z_]{1,12}", text in ".{0,32}", client in "[0-9]{1,6}-[0-9]{1,3}") {
            let r = Request::SetParam { skill, param, value: ParamArg::Text(text) };
            let env = decode_request(&encode_request(&client, 3, &r).unwrap()).unwrap();
            proptest::prop_assert_eq!(env.request, r);
            proptest::prop_assert_eq!(env.client, client);
        }
    }

    #[test]
    fn arbitrary_bytes_never_panic_the_decoder() {
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        for len in 0..2000usize {
            let bytes: Vec<u8> = (0..len % 64)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    x as u8
                })
                .collect();
            let mut versioned = vec![PROTOCOL_VERSION as u8];
            versioned.extend_from_slice(&bytes);
            let _ = decode_request(&bytes);
            let _ = decode_request(&versioned);
            let _ = decode_response(&bytes);
            let _ = decode_event(&bytes);
        }
    }
}
