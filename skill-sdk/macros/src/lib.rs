//! Derive macros of `skill-sdk`. Skill authors use them through `skill_sdk::prelude`.
//!
//! Layout: one function per derive. Every generated path goes through `::skill_sdk` (its
//! hidden `__private` module for the wire types) so a skill crate depends on `skill-sdk` alone
//! (it never names iceoryx2 or `skillfab-proto`). `skillfab-proto` derives its own messages
//! with `#[message(crate = "crate")]`.
//!
//! - [`Message`]: `#[repr(C)]` data types: the iceoryx2 `ZeroCopySend` impl with an explicit
//!   type name (`#[message(type_name = "...")]`, default `skillfab.<Ident>`) and a run-time
//!   schema (field names, types, offsets).
//! - [`Params`]: a parameter struct: `#[param(default = .., min = .., max = ..)]` per field,
//!   doc comments become the parameter's doc.
//! - [`Inputs`] / [`Outputs`]: a struct of `Input<'a, T>` / `Output<'a, T>` fields, one per port.
//! - [`Channels`]: a device's struct of `Command<'a, T>` fields, one per actuator channel.

#![warn(missing_docs)]

use proc_macro::TokenStream;
use quote::{ToTokens, quote};
use syn::{Data, DeriveInput, Expr, Fields, Lit, parse_macro_input, spanned::Spanned};

fn named_fields(input: &DeriveInput) -> syn::Result<Vec<&syn::Field>> {
    match &input.data {
        Data::Struct(s) => match &s.fields {
            Fields::Named(f) => Ok(f.named.iter().collect()),
            Fields::Unit => Ok(Vec::new()),
            Fields::Unnamed(_) => Err(syn::Error::new(
                input.span(),
                "skill-sdk derives need a struct with named fields",
            )),
        },
        _ => Err(syn::Error::new(
            input.span(),
            "skill-sdk derives only work on structs",
        )),
    }
}

/// `ty` as it must be written again: the length of an array written with a `macro_rules!`
/// fragment (`[u8; $bytes - 8]` with `$bytes` = `64 << 10`) holds the fragment in an invisible
/// group, which the compiler drops when it reads the derive's output again (rust-lang/rust
/// #67062): `[u8; 64 << 10 - 8]`, 256 bytes. Invisible groups in array lengths become
/// parentheses.
fn plain_type(ty: &syn::Type) -> syn::Type {
    fn parenthesised(tokens: proc_macro2::TokenStream) -> proc_macro2::TokenStream {
        use proc_macro2::{Delimiter, Group, TokenTree};
        tokens
            .into_iter()
            .map(|t| match t {
                TokenTree::Group(g) => {
                    let delimiter = match g.delimiter() {
                        Delimiter::None => Delimiter::Parenthesis,
                        d => d,
                    };
                    let mut out = Group::new(delimiter, parenthesised(g.stream()));
                    out.set_span(g.span());
                    TokenTree::Group(out)
                }
                other => other,
            })
            .collect()
    }
    match ty {
        syn::Type::Array(a) => {
            let elem = plain_type(&a.elem);
            let len = parenthesised(a.len.to_token_stream());
            syn::parse_quote!([#elem; #len])
        }
        syn::Type::Group(g) => plain_type(&g.elem),
        other => other.clone(),
    }
}

fn doc_of(attrs: &[syn::Attribute]) -> String {
    let mut lines = Vec::new();
    for a in attrs {
        if a.path().is_ident("doc")
            && let syn::Meta::NameValue(nv) = &a.meta
            && let Expr::Lit(l) = &nv.value
            && let Lit::Str(s) = &l.lit
        {
            lines.push(s.value().trim().to_string());
        }
    }
    lines.join(" ")
}

/// A `#[repr(C)]` message type: zero-copy across processes, with a schema.
#[proc_macro_derive(Message, attributes(message))]
pub fn derive_message(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    match message(&input) {
        Ok(t) => t.into(),
        Err(e) => e.to_compile_error().into(),
    }
}

fn message(input: &DeriveInput) -> syn::Result<proc_macro2::TokenStream> {
    let ident = &input.ident;
    if !input.generics.params.is_empty() {
        return Err(syn::Error::new(
            input.generics.span(),
            "a Message cannot be generic",
        ));
    }
    let has_repr_c = input.attrs.iter().any(|a| {
        a.path().is_ident("repr")
            && a.parse_args_with(
                syn::punctuated::Punctuated::<syn::Meta, syn::Token![,]>::parse_terminated,
            )
            .map(|list| list.iter().any(|m| m.path().is_ident("C")))
            .unwrap_or(false)
    });
    if !has_repr_c {
        return Err(syn::Error::new(
            input.span(),
            "a Message must be #[repr(C)] so every process and language sees one layout",
        ));
    }
    let mut type_name = format!("skillfab.{ident}");
    let mut krate: syn::Path = syn::parse_quote!(::skill_sdk::__private::proto);
    for a in input.attrs.iter().filter(|a| a.path().is_ident("message")) {
        a.parse_nested_meta(|meta| {
            if meta.path.is_ident("type_name") {
                let s: syn::LitStr = meta.value()?.parse()?;
                type_name = s.value();
                Ok(())
            } else if meta.path.is_ident("crate") {
                let s: syn::LitStr = meta.value()?.parse()?;
                krate = s.parse()?;
                Ok(())
            } else {
                Err(meta.error("expected `type_name = \"...\"` or `crate = \"...\"`"))
            }
        })?;
    }
    let fields = named_fields(input)?;
    let doc = doc_of(&input.attrs);
    let mut schema_fields = Vec::new();
    let mut checks = Vec::new();
    for f in &fields {
        let name = f.ident.as_ref().map(|i| i.to_string()).unwrap_or_default();
        let fid = &f.ident;
        let ty = &plain_type(&f.ty);
        schema_fields.push(quote! {
            #krate::schema::FieldSchema {
                name: #name.to_string(),
                offset: ::core::mem::offset_of!(#ident, #fid) as u32,
                ty: <#ty as #krate::schema::FieldType>::field_type(),
            }
        });
        checks.push(quote! { assert_field::<#ty>(); });
    }
    Ok(quote! {
        // SAFETY: the type is #[repr(C)] and every field is a `FieldType` (checked below), which
        // only plain-old-data types implement: it has no pointers and one layout everywhere.
        unsafe impl #krate::__private::ZeroCopySend for #ident {
            unsafe fn type_name() -> &'static str { #type_name }
        }
        // SAFETY: as above; every `FieldType` is valid when all its bytes are zero.
        unsafe impl #krate::schema::FieldType for #ident {
            fn field_type() -> #krate::schema::FieldKind {
                #krate::schema::FieldKind::Struct(<Self as #krate::Message>::schema())
            }
        }
        impl #krate::Message for #ident {
            const TYPE_NAME: &'static str = #type_name;
            fn schema() -> #krate::schema::MessageSchema {
                #krate::schema::MessageSchema {
                    type_name: #type_name.to_string(),
                    doc: #doc.to_string(),
                    size: ::core::mem::size_of::<Self>() as u32,
                    align: ::core::mem::align_of::<Self>() as u32,
                    fields: vec![#(#schema_fields),*],
                }
            }
        }
        const _: () = {
            const fn assert_field<T: #krate::schema::FieldType>() {}
            #(#checks)*
        };
    })
}

/// A skill's parameter struct: typed fields with default, bounds and doc.
#[proc_macro_derive(Params, attributes(param))]
pub fn derive_params(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    match params(&input) {
        Ok(t) => t.into(),
        Err(e) => e.to_compile_error().into(),
    }
}

fn params(input: &DeriveInput) -> syn::Result<proc_macro2::TokenStream> {
    let ident = &input.ident;
    let fields = named_fields(input)?;
    let mut specs = Vec::new();
    let mut defaults = Vec::new();
    let mut gets = Vec::new();
    let mut sets = Vec::new();
    for f in &fields {
        let fid = f
            .ident
            .as_ref()
            .ok_or_else(|| syn::Error::new(f.span(), "unnamed field"))?;
        let name = fid.to_string();
        let ty = &f.ty;
        let doc = doc_of(&f.attrs);
        let mut default: Option<Expr> = None;
        let mut min: Option<Expr> = None;
        let mut max: Option<Expr> = None;
        for a in f.attrs.iter().filter(|a| a.path().is_ident("param")) {
            a.parse_nested_meta(|meta| {
                let slot = if meta.path.is_ident("default") {
                    &mut default
                } else if meta.path.is_ident("min") {
                    &mut min
                } else if meta.path.is_ident("max") {
                    &mut max
                } else {
                    return Err(meta.error("expected `default`, `min` or `max`"));
                };
                *slot = Some(meta.value()?.parse()?);
                Ok(())
            })?;
        }
        let default = default.ok_or_else(|| {
            syn::Error::new(
                f.span(),
                format!("parameter `{name}` needs #[param(default = ...)]"),
            )
        })?;
        let to_bound = |e: &Option<Expr>| match e {
            Some(e) => quote! { Some(::skill_sdk::params::ParamType::to_value(&(#e as #ty))) },
            None => quote! { None },
        };
        let (min_t, max_t) = (to_bound(&min), to_bound(&max));
        specs.push(quote! {
            ::skill_sdk::params::ParamSpec {
                name: #name.to_string(),
                kind: <#ty as ::skill_sdk::params::ParamType>::KIND,
                default: ::skill_sdk::params::ParamType::to_value(&(#default as #ty)),
                min: #min_t,
                max: #max_t,
                doc: #doc.to_string(),
            }
        });
        defaults.push(quote! { #fid: (#default as #ty) });
        gets.push(quote! { #name => Some(::skill_sdk::params::ParamType::to_value(&self.#fid)), });
        sets.push(quote! {
            #name => {
                self.#fid = <#ty as ::skill_sdk::params::ParamType>::from_value(&value)
                    .ok_or_else(|| ::skill_sdk::params::ParamError::WrongType {
                        param: #name.to_string(),
                        expected: <#ty as ::skill_sdk::params::ParamType>::KIND,
                        got: value.clone(),
                    })?;
                Ok(())
            }
        });
    }
    Ok(quote! {
        impl ::core::default::Default for #ident {
            fn default() -> Self { Self { #(#defaults),* } }
        }
        impl ::skill_sdk::params::Params for #ident {
            fn specs(&self) -> ::std::vec::Vec<::skill_sdk::params::ParamSpec> { vec![#(#specs),*] }
            fn get(&self, name: &str) -> ::core::option::Option<::skill_sdk::params::ParamValue> {
                match name { #(#gets)* _ => None }
            }
            fn set_unchecked(
                &mut self,
                name: &str,
                value: ::skill_sdk::params::ParamValue,
            ) -> ::core::result::Result<(), ::skill_sdk::params::ParamError> {
                match name {
                    #(#sets)*
                    _ => Err(::skill_sdk::params::ParamError::Unknown { param: name.to_string() }),
                }
            }
        }
    })
}

/// A skill's inputs: a struct of `Input<'a, T>` fields; the field name is the topic.
#[proc_macro_derive(Inputs)]
pub fn derive_inputs(input: TokenStream) -> TokenStream {
    derive_ports(input, PortSet::Inputs)
}

/// A skill's outputs: a struct of `Output<'a, T>` fields; the field name is the topic.
#[proc_macro_derive(Outputs)]
pub fn derive_outputs(input: TokenStream) -> TokenStream {
    derive_ports(input, PortSet::Outputs)
}

/// A device's channels: a struct of `Command<'a, T>` fields; the field name is the channel.
#[proc_macro_derive(Channels)]
pub fn derive_channels(input: TokenStream) -> TokenStream {
    derive_ports(input, PortSet::Channels)
}

/// Which set of ports a struct declares.
#[derive(Clone, Copy)]
enum PortSet {
    Inputs,
    Outputs,
    Channels,
}

fn derive_ports(input: TokenStream, set: PortSet) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    match ports(&input, set) {
        Ok(t) => t.into(),
        Err(e) => e.to_compile_error().into(),
    }
}

fn ports(input: &DeriveInput, set: PortSet) -> syn::Result<proc_macro2::TokenStream> {
    let ident = &input.ident;
    let lifetimes: Vec<_> = input.generics.lifetimes().collect();
    if lifetimes.len() != 1 || input.generics.params.len() != 1 {
        return Err(syn::Error::new(
            input.generics.span(),
            "a port struct takes exactly one lifetime parameter, e.g. `struct In<'a>`",
        ));
    }
    let lt = &lifetimes[0].lifetime;
    let fields = named_fields(input)?;
    let mut decls = Vec::new();
    let mut builds = Vec::new();
    let mut makes = Vec::new();
    for (idx, f) in fields.iter().enumerate() {
        let fid = f
            .ident
            .as_ref()
            .ok_or_else(|| syn::Error::new(f.span(), "unnamed field"))?;
        let name = fid.to_string();
        let ty = &f.ty;
        let field = match set {
            PortSet::Inputs => quote! { ::skill_sdk::ports::InputField<#lt> },
            PortSet::Outputs => quote! { ::skill_sdk::ports::OutputField<#lt> },
            PortSet::Channels => quote! { ::skill_sdk::actuation::ChannelField<#lt> },
        };
        decls.push(quote! { <#ty as #field>::decl(#name) });
        builds.push(match set {
            PortSet::Inputs => quote! { #fid: <#ty as #field>::fetch(src, #idx)? },
            PortSet::Outputs => quote! { #fid: <#ty as #field>::bind(slots.take_next()) },
            PortSet::Channels => quote! { #fid: <#ty as #field>::fetch(channels, #idx)? },
        });
        makes.push(quote! { <#ty as #field>::make(maker, #idx)? });
    }
    let decl = quote! { ::skill_sdk::__private::proto::decl::PortDecl };
    let error = quote! { ::skill_sdk::SdkError };
    Ok(match set {
        PortSet::Inputs => quote! {
            impl<#lt> ::skill_sdk::ports::InputSet<#lt> for #ident<#lt> {
                fn ports() -> ::std::vec::Vec<#decl> { vec![#(#decls),*] }
                fn fetch(src: &#lt dyn ::skill_sdk::ports::InputSource) -> ::core::option::Option<Self> {
                    Some(Self { #(#builds),* })
                }
                fn make(maker: &::skill_sdk::ports::PortMaker<'_>)
                    -> ::core::result::Result<::std::vec::Vec<::std::boxed::Box<dyn ::skill_sdk::ports::ErasedInput>>, #error> {
                    Ok(vec![#(#makes),*])
                }
            }
        },
        PortSet::Outputs => quote! {
            impl<#lt> ::skill_sdk::ports::OutputSet<#lt> for #ident<#lt> {
                fn ports() -> ::std::vec::Vec<#decl> { vec![#(#decls),*] }
                fn bind(slots: &#lt mut [::skill_sdk::ports::ErasedOutput]) -> Self {
                    let mut slots = ::skill_sdk::ports::OutputSlots::new(slots);
                    Self { #(#builds),* }
                }
                fn make(maker: &::skill_sdk::ports::PortMaker<'_>)
                    -> ::core::result::Result<::std::vec::Vec<::skill_sdk::ports::ErasedOutput>, #error> {
                    Ok(vec![#(#makes),*])
                }
            }
        },
        PortSet::Channels => quote! {
            impl<#lt> ::skill_sdk::actuation::ChannelSet<#lt> for #ident<#lt> {
                fn ports() -> ::std::vec::Vec<#decl> { vec![#(#decls),*] }
                fn fetch(channels: &#lt [::std::boxed::Box<dyn ::skill_sdk::actuation::ErasedChannel>])
                    -> ::core::option::Option<Self> {
                    Some(Self { #(#builds),* })
                }
                fn make(maker: &::skill_sdk::ports::PortMaker<'_>)
                    -> ::core::result::Result<::std::vec::Vec<::std::boxed::Box<dyn ::skill_sdk::actuation::ErasedChannel>>, #error> {
                    Ok(vec![#(#makes),*])
                }
            }
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_array_length_from_a_macro_fragment_keeps_its_grouping() {
        // What `[u8; $bytes - 8]` is with `$bytes` = `64 << 10`, inside `macro_rules!`.
        let bytes = proc_macro2::Group::new(proc_macro2::Delimiter::None, quote!(64 << 10));
        let input: DeriveInput = syn::parse_quote! {
            #[repr(C)]
            pub struct Blob { data: [u8; #bytes - 8] }
        };
        let text = message(&input).unwrap().to_string().replace(' ', "");
        assert!(text.contains("<[u8;(64<<10)-8]as"), "{text}");
    }
}
