#![allow(missing_docs)]
//! SDO throughput in memory (CiA 301 §7.2.4): upload of a 4 kB object, segmented (one
//! request per 7 bytes) vs block (127 segments per acknowledgement), client and server
//! passing frames directly. Criterion's throughput line reports bytes/s of object data.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use fieldprobe::bus::can::CanFrame;
use fieldprobe::bus::canopen::sdo::{ObjectAccess, SdoClient, SdoServer, TransferMode};
use fieldprobe::units::Nanos;

const SIZE: usize = 4096;

struct Od(Vec<u8>);

impl ObjectAccess for Od {
    fn read(&mut self, _index: u16, _sub: u8) -> Result<Vec<u8>, u32> {
        Ok(self.0.clone())
    }
    fn write(&mut self, _index: u16, _sub: u8, data: &[u8]) -> Result<(), u32> {
        self.0 = data.to_vec();
        Ok(())
    }
}

/// One upload, frames handed over until the client has its result.
fn upload(client: &mut SdoClient, server: &mut SdoServer, od: &mut Od) -> usize {
    let now = Nanos::ZERO;
    let mut to_server: Vec<CanFrame> = client.upload(0x2000, 1, now);
    while !to_server.is_empty() {
        let mut to_client = Vec::new();
        for f in &to_server {
            to_client.extend(server.handle(f, od, now));
        }
        to_server.clear();
        for f in &to_client {
            to_server.extend(client.handle(f, now));
        }
    }
    match client.take_result() {
        Some(Ok(data)) => data.len(),
        other => panic!("upload failed: {other:?}"),
    }
}

fn bench_sdo(c: &mut Criterion) {
    let data: Vec<u8> = (0..SIZE).map(|i| i as u8).collect();
    let mut g = c.benchmark_group("canopen_sdo_upload_4k");
    g.throughput(Throughput::Bytes(SIZE as u64));
    for (name, mode) in [
        ("segmented", TransferMode::Segmented),
        ("block", TransferMode::Block),
    ] {
        let mut client = SdoClient::new(5);
        client.set_mode(mode);
        let mut server = SdoServer::new(5);
        let mut od = Od(data.clone());
        assert_eq!(upload(&mut client, &mut server, &mut od), SIZE);
        g.bench_function(name, |b| {
            b.iter(|| black_box(upload(&mut client, &mut server, &mut od)))
        });
    }
    g.finish();
}

criterion_group!(benches, bench_sdo);
criterion_main!(benches);
