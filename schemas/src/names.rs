//! Enums named by `strum` on the command line, in scene files and in results files
//! ([`Named`]), and the one error for a name that is none of theirs ([`UnknownName`]), which
//! lists the known names from the variants themselves (`strum::VariantNames`). Each such enum
//! derives `strum::EnumString` with `parse_err_ty = UnknownName<Self>` and
//! `parse_err_fn = UnknownName::new`, so that `str::parse` gives this error, and gets its
//! inherent `name()` (and `ALL`) from the [`strum_names!`](crate::strum_names) macro.

use std::marker::PhantomData;

/// An enum whose variants `strum` names (`VariantNames`), with the noun that an unknown name
/// is reported as (`unknown method 'x' (...)`).
pub trait Named: strum::VariantNames {
    /// What one variant is, in error messages: `method`, `experiment`, `filter`, ...
    const NOUN: &'static str;
}

/// A name that is none of `E`'s: `unknown NOUN 'name' (a, b or c)`, listing `E`'s names in
/// the order of its variants.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown {} '{name}' ({})",
    E::NOUN,
    one_of(<E as strum::VariantNames>::VARIANTS)
)]
pub struct UnknownName<E: Named> {
    /// The name given.
    pub name: String,
    kind: PhantomData<E>,
}

impl<E: Named> UnknownName<E> {
    /// The error for the name `name`.
    pub fn new(name: &str) -> Self {
        Self {
            name: name.to_string(),
            kind: PhantomData,
        }
    }
}

/// Writes the inherent `name()` of an enum that derives `strum::IntoStaticStr` (the name on
/// the command line, in scene and results files) and, with `all`, its `ALL` (every variant in
/// the order of declaration, from `strum::VariantArray` and `strum::EnumCount`), so that no
/// enum writes them out by hand: `residency_schemas::strum_names!(Method, all);`.
#[macro_export]
macro_rules! strum_names {
    ($ty:ty) => {
        impl $ty {
            /// The variant's name: on the command line, in scene files and in results files.
            pub fn name(self) -> &'static str {
                self.into()
            }
        }
    };
    ($ty:ty, all) => {
        $crate::strum_names!($ty);
        impl $ty {
            /// Every variant, in the order of declaration.
            pub const ALL: [Self; <Self as $crate::strum::EnumCount>::COUNT] =
                *<Self as $crate::strum::VariantArray>::VARIANTS
                    .first_chunk()
                    .expect("one entry per variant");
        }
    };
}

/// `names` as a list to pick one from: `a, b or c`.
fn one_of(names: &[&str]) -> String {
    match names {
        [] => String::new(),
        [only] => (*only).to_string(),
        [rest @ .., last] => format!("{} or {last}", rest.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::one_of;

    #[test]
    fn names_are_listed_with_or_before_the_last() {
        assert_eq!(one_of(&[]), "");
        assert_eq!(one_of(&["a"]), "a");
        assert_eq!(one_of(&["a", "b"]), "a or b");
        assert_eq!(one_of(&["a", "b", "c"]), "a, b or c");
    }
}
