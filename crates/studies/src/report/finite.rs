//! Checking that every number about to be written is finite (serde_json writes NaN and ±∞ as
//! `null`, which would pass a broken figure off as "not reported").

use serde::ser::{self, Serialize};

/// A non-finite number found in a value about to be written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path} is {value}, not a finite number")]
pub struct NonFinite {
    /// Where in the value: field names and `[index]`es, e.g. `cold.return_at_budget.per_seed[2]`.
    pub path: String,
    /// The number (NaN, inf or -inf).
    pub value: f64,
}

impl NonFinite {
    /// The same error with `prefix.` before the path (for a value inside a larger one).
    pub fn within(mut self, prefix: &str) -> Self {
        self.path = format!("{prefix}.{}", self.path);
        self
    }
}

impl ser::Error for NonFinite {
    fn custom<T: std::fmt::Display>(msg: T) -> Self {
        NonFinite {
            path: msg.to_string(),
            value: f64::NAN,
        }
    }
}

/// Checks every floating-point number in `value` (as serde sees it); the first non-finite one
/// is an error naming where it is.
pub fn ensure_finite<T: Serialize + ?Sized>(value: &T) -> Result<(), NonFinite> {
    let mut c = Checker::default();
    match value.serialize(&mut c) {
        Ok(()) => Ok(()),
        Err(mut e) if e.value.is_nan() && !c.failed => {
            // A serializer error of the value's own (not a number): report as is.
            e.path = format!("cannot serialize: {}", e.path);
            Err(e)
        }
        Err(e) => Err(e),
    }
}

/// Walks a value, keeping the path to the current number.
#[derive(Default)]
struct Checker {
    path: Vec<String>,
    index: Vec<usize>,
    failed: bool,
}

impl Checker {
    fn float(&mut self, v: f64) -> Result<(), NonFinite> {
        if v.is_finite() {
            return Ok(());
        }
        self.failed = true;
        let mut path = String::new();
        for seg in &self.path {
            if !path.is_empty() && !seg.starts_with('[') {
                path.push('.');
            }
            path.push_str(seg);
        }
        Err(NonFinite {
            path: if path.is_empty() {
                "the value".into()
            } else {
                path
            },
            value: v,
        })
    }

    fn nested<T: Serialize + ?Sized>(&mut self, seg: String, v: &T) -> Result<(), NonFinite> {
        self.path.push(seg);
        v.serialize(&mut *self)?;
        self.path.pop();
        Ok(())
    }

    fn element<T: Serialize + ?Sized>(&mut self, v: &T) -> Result<(), NonFinite> {
        let i = self.index.last_mut().map_or(0, |i| {
            *i += 1;
            *i - 1
        });
        self.nested(format!("[{i}]"), v)
    }

    fn open(&mut self) {
        self.index.push(0);
    }

    fn close(&mut self) -> Result<(), NonFinite> {
        self.index.pop();
        Ok(())
    }
}

/// A map key as text (JSON's view of it).
fn key_text<T: Serialize + ?Sized>(key: &T) -> String {
    match serde_json::to_value(key) {
        Ok(serde_json::Value::String(s)) => s,
        Ok(v) => v.to_string(),
        Err(_) => "?".into(),
    }
}

macro_rules! ok_scalars {
    ($($f:ident: $t:ty),*) => {
        $(fn $f(self, _: $t) -> Result<(), NonFinite> { Ok(()) })*
    };
}

impl ser::Serializer for &mut Checker {
    type Ok = ();
    type Error = NonFinite;
    type SerializeSeq = Self;
    type SerializeTuple = Self;
    type SerializeTupleStruct = Self;
    type SerializeTupleVariant = Self;
    type SerializeMap = Self;
    type SerializeStruct = Self;
    type SerializeStructVariant = Self;

    ok_scalars!(serialize_bool: bool, serialize_i8: i8, serialize_i16: i16, serialize_i32: i32,
        serialize_i64: i64, serialize_u8: u8, serialize_u16: u16, serialize_u32: u32,
        serialize_u64: u64, serialize_char: char, serialize_str: &str, serialize_bytes: &[u8],
        serialize_unit_struct: &'static str);

    fn serialize_f32(self, v: f32) -> Result<(), NonFinite> {
        self.float(f64::from(v))
    }
    fn serialize_f64(self, v: f64) -> Result<(), NonFinite> {
        self.float(v)
    }
    fn serialize_none(self) -> Result<(), NonFinite> {
        Ok(())
    }
    fn serialize_some<T: Serialize + ?Sized>(self, v: &T) -> Result<(), NonFinite> {
        v.serialize(self)
    }
    fn serialize_unit(self) -> Result<(), NonFinite> {
        Ok(())
    }
    fn serialize_unit_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
    ) -> Result<(), NonFinite> {
        Ok(())
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        v: &T,
    ) -> Result<(), NonFinite> {
        v.serialize(self)
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        v: &T,
    ) -> Result<(), NonFinite> {
        self.nested(variant.to_string(), v)
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Self, NonFinite> {
        self.open();
        Ok(self)
    }
    fn serialize_tuple(self, _: usize) -> Result<Self, NonFinite> {
        self.open();
        Ok(self)
    }
    fn serialize_tuple_struct(self, _: &'static str, _: usize) -> Result<Self, NonFinite> {
        self.open();
        Ok(self)
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Self, NonFinite> {
        self.path.push(variant.to_string());
        self.open();
        Ok(self)
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Self, NonFinite> {
        self.path.push(String::new());
        Ok(self)
    }
    fn serialize_struct(self, _: &'static str, _: usize) -> Result<Self, NonFinite> {
        Ok(self)
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Self, NonFinite> {
        self.path.push(variant.to_string());
        Ok(self)
    }
}

/// The serializers of sequences and tuples: each element is checked under `[i]`; `end` closes the
/// index (and, for a tuple variant, the variant's name that opening it pushed).
macro_rules! element_serializers {
    ($($serializer:ident::$method:ident, pops_variant: $pops:literal;)*) => {$(
        impl ser::$serializer for &mut Checker {
            type Ok = ();
            type Error = NonFinite;
            fn $method<T: Serialize + ?Sized>(&mut self, v: &T) -> Result<(), NonFinite> {
                self.element(v)
            }
            fn end(self) -> Result<(), NonFinite> {
                if $pops {
                    self.path.pop();
                }
                self.close()
            }
        }
    )*};
}

element_serializers! {
    SerializeSeq::serialize_element, pops_variant: false;
    SerializeTuple::serialize_element, pops_variant: false;
    SerializeTupleStruct::serialize_field, pops_variant: false;
    SerializeTupleVariant::serialize_field, pops_variant: true;
}

impl ser::SerializeMap for &mut Checker {
    type Ok = ();
    type Error = NonFinite;
    fn serialize_key<T: Serialize + ?Sized>(&mut self, key: &T) -> Result<(), NonFinite> {
        if let Some(last) = self.path.last_mut() {
            *last = key_text(key);
        }
        Ok(())
    }
    fn serialize_value<T: Serialize + ?Sized>(&mut self, v: &T) -> Result<(), NonFinite> {
        v.serialize(&mut **self)
    }
    fn end(self) -> Result<(), NonFinite> {
        self.path.pop();
        Ok(())
    }
}

/// The serializers of structs: each field is checked under its name; a struct variant's `end`
/// pops the variant's name that opening it pushed.
macro_rules! field_serializers {
    ($($serializer:ident, pops_variant: $pops:literal;)*) => {$(
        impl ser::$serializer for &mut Checker {
            type Ok = ();
            type Error = NonFinite;
            fn serialize_field<T: Serialize + ?Sized>(
                &mut self,
                key: &'static str,
                v: &T,
            ) -> Result<(), NonFinite> {
                self.nested(key.to_string(), v)
            }
            fn end(self) -> Result<(), NonFinite> {
                if $pops {
                    self.path.pop();
                }
                Ok(())
            }
        }
    )*};
}

field_serializers! {
    SerializeStruct, pops_variant: false;
    SerializeStructVariant, pops_variant: true;
}

/// `value` as pretty JSON, or an error naming its first non-finite number.
pub fn to_json_pretty<T: Serialize + ?Sized>(value: &T) -> Result<String, NonFinite> {
    ensure_finite(value)?;
    serde_json::to_string_pretty(value).map_err(|e| NonFinite {
        path: format!("cannot serialize: {e}"),
        value: f64::NAN,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    #[derive(serde::Serialize)]
    struct Inner {
        per_seed: Vec<Option<f64>>,
    }

    #[derive(serde::Serialize)]
    struct Outer {
        name: &'static str,
        steps: u64,
        inner: BTreeMap<String, Inner>,
        pair: (f32, f64),
    }

    fn outer(bad: f64, pair_bad: f64) -> Outer {
        let mut inner = BTreeMap::new();
        inner.insert(
            "a".to_string(),
            Inner {
                per_seed: vec![Some(1.0), None],
            },
        );
        inner.insert(
            "b".to_string(),
            Inner {
                per_seed: vec![Some(2.0), None, Some(bad)],
            },
        );
        Outer {
            name: "x",
            steps: 3,
            inner,
            pair: (0.5, pair_bad),
        }
    }

    #[test]
    fn finite_values_pass_and_the_first_bad_number_is_named() {
        assert_eq!(ensure_finite(&outer(3.0, 1.0)), Ok(()));
        let e = ensure_finite(&outer(f64::NAN, 1.0)).unwrap_err();
        assert_eq!(e.path, "inner.b.per_seed[2]");
        assert!(e.value.is_nan());
        let e = ensure_finite(&outer(1.0, f64::NEG_INFINITY)).unwrap_err();
        assert_eq!((e.path.as_str(), e.value), ("pair[1]", f64::NEG_INFINITY));
        assert_eq!(e.to_string(), "pair[1] is -inf, not a finite number");
        assert!(ensure_finite(&serde_json::json!({"k": [1, 2.5, null]})).is_ok());
        assert_eq!(ensure_finite(&f64::INFINITY).unwrap_err().path, "the value");
        // Tuple structs, tuple and struct variants: each closes what it opened, so a later bad
        // number is named without them.
        #[derive(serde::Serialize)]
        struct Pair(f64, f64);
        #[derive(serde::Serialize)]
        enum Shape {
            Tuple(f64, f64),
            Struct { w: f64 },
        }
        assert_eq!(ensure_finite(&Pair(1.0, f64::NAN)).unwrap_err().path, "[1]");
        let tuple = Shape::Tuple(0.0, f64::INFINITY);
        assert_eq!(ensure_finite(&tuple).unwrap_err().path, "Tuple[1]");
        let fields = Shape::Struct { w: f64::NAN };
        assert_eq!(ensure_finite(&fields).unwrap_err().path, "Struct.w");
        let after = (
            Shape::Tuple(1.0, 2.0),
            Shape::Struct { w: 3.0 },
            Pair(0.0, 0.0),
            f64::NAN,
        );
        assert_eq!(ensure_finite(&after).unwrap_err().path, "[3]");
        // The text written for a good value is serde_json's.
        assert_eq!(
            to_json_pretty(&[1.5, 2.0]).unwrap(),
            serde_json::to_string_pretty(&[1.5, 2.0]).unwrap()
        );
    }
}
