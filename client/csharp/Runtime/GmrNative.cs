// The C ABI of the gmr client (client/c/include/gmr_client_c.h), declared for
// P/Invoke: the way a Unity plugin, or any .NET program, loads native code.
// Struct layouts mirror the header field for field (sequential, natural
// alignment, as the C compiler lays them out on every 64-bit target). Strings
// cross as NUL-terminated UTF-8 byte arrays, never through the runtime's
// "ANSI" marshalling, which is not UTF-8 on Windows.
using System;
using System.Runtime.InteropServices;
using System.Text;

namespace Gmr
{
    internal static class Native
    {
        // libgmr_client_c.so (Linux), libgmr_client_c.dylib (macOS),
        // gmr_client_c.dll (Windows): Unity and Mono add the prefix and suffix.
        private const string Lib = "gmr_client_c";

        public const int AbiVersion = 1;

        [StructLayout(LayoutKind.Sequential)]
        public struct MotionInfo
        {
            [MarshalAs(UnmanagedType.ByValArray, SizeConst = 256)] public byte[] name;
            public uint joint_count;
            public ulong frame_count;
            public double frame_time;
            public double metres_per_unit;
        }

        [StructLayout(LayoutKind.Sequential)]
        public struct JointInfo
        {
            [MarshalAs(UnmanagedType.ByValArray, SizeConst = 128)] public byte[] name;
            public int parent;
            [MarshalAs(UnmanagedType.ByValArray, SizeConst = 3)] public double[] rest_translation;
            [MarshalAs(UnmanagedType.ByValArray, SizeConst = 4)] public double[] rest_rotation;
        }

        [StructLayout(LayoutKind.Sequential)]
        public struct PublishJoint
        {
            public IntPtr name;  // NUL-terminated UTF-8, owned by the caller for the call
            public int parent;
            [MarshalAs(UnmanagedType.ByValArray, SizeConst = 3)] public double[] offset;
            public uint channel_count;
            [MarshalAs(UnmanagedType.ByValArray, SizeConst = 6)] public int[] channels;
        }

        [StructLayout(LayoutKind.Sequential)]
        public struct RoleJoint
        {
            public IntPtr role;
            public IntPtr joint;
        }

        [StructLayout(LayoutKind.Sequential)]
        public struct SubscribeOptions
        {
            public uint struct_size;
            public double rate_hz;
            public double speed;
            public int loop;
            public int udp;
            public int float64;
            public int local_transforms;
            public int orientations;
            public ulong max_frames;
            public uint start_frame;
            public uint end_frame;
            public int preset;
            public double source_metres_per_unit;
            public uint max_staleness_ms;
        }

        [StructLayout(LayoutKind.Sequential)]
        public struct Frame
        {
            public ulong frame_index;
            public double motion_time;
            public ulong sequence;
            public long server_send_time_ns;
            public uint skeleton_version;
            public uint joint_count;
            public int skeleton_changed;
            public int has_local_transforms;
            public int has_orientations;
        }

        [DllImport(Lib)] public static extern IntPtr gmr_last_error();
        [DllImport(Lib)] public static extern int gmr_abi_version();
        [DllImport(Lib)] public static extern int gmr_connect(byte[] host, ushort port, byte[] token, out IntPtr client);
        [DllImport(Lib)] public static extern void gmr_disconnect(IntPtr client);
        [DllImport(Lib)] public static extern int gmr_list_motions(IntPtr client, [Out] MotionInfo[] output, UIntPtr capacity, out UIntPtr count);
        [DllImport(Lib)] public static extern int gmr_create_view(IntPtr client, byte[] motion, out uint viewId);
        [DllImport(Lib)] public static extern int gmr_close_view(IntPtr client, uint viewId);
        [DllImport(Lib)] public static extern int gmr_shift_root(IntPtr client, uint viewId, byte[] joint);
        [DllImport(Lib)] public static extern int gmr_set_roots(IntPtr client, uint viewId, IntPtr[] roots, UIntPtr count);
        [DllImport(Lib)] public static extern int gmr_split(IntPtr client, uint viewId, byte[] joint);
        [DllImport(Lib)] public static extern int gmr_join(IntPtr client, uint viewId, byte[] root);
        [DllImport(Lib)] public static extern int gmr_strip_dummies(IntPtr client, uint viewId);
        [DllImport(Lib)] public static extern int gmr_set_viewpoint(IntPtr client, uint viewId, byte[] joint);
        [DllImport(Lib)] public static extern int gmr_retarget_mapped(IntPtr client, uint viewId, PublishJoint[] joints, UIntPtr jointCount,
                                                                      double[] reference, UIntPtr referenceCount,
                                                                      RoleJoint[] rigMap, UIntPtr rigMapCount,
                                                                      RoleJoint[] sourceMap, UIntPtr sourceMapCount,
                                                                      double metresPerUnit);
        [DllImport(Lib)] public static extern int gmr_query_positions(IntPtr client, uint viewId, uint begin, uint end, int preset,
                                                                     [Out] double[] positions, UIntPtr capacity, out UIntPtr jointCount);
        [DllImport(Lib)] public static extern void gmr_subscribe_options_init(ref SubscribeOptions options);
        [DllImport(Lib)] public static extern int gmr_subscribe(IntPtr client, uint viewId, ref SubscribeOptions options, out IntPtr subscription);
        [DllImport(Lib)] public static extern void gmr_unsubscribe(IntPtr subscription);
        [DllImport(Lib)] public static extern int gmr_subscription_joint_count(IntPtr subscription, out UIntPtr count);
        [DllImport(Lib)] public static extern int gmr_subscription_metres_per_unit(IntPtr subscription, out double metresPerUnit);
        [DllImport(Lib)] public static extern int gmr_subscription_joint(IntPtr subscription, UIntPtr index, ref JointInfo output);
        [DllImport(Lib)] public static extern int gmr_poll_frame(IntPtr subscription, ref Frame frame, [Out] double[] positions,
                                                                [Out] double[] orientations, [Out] double[] localRotations,
                                                                [Out] double[] localTranslations, UIntPtr capacity);
        [DllImport(Lib)] public static extern int gmr_last_frame_times(IntPtr subscription, out long serverSendTimeNs,
                                                                      out long serverWriteTimeNs, out long receiveTimeNs);
        [DllImport(Lib)] public static extern int gmr_subscription_counts(IntPtr subscription, out ulong received, out ulong replaced);

        /// <summary>A string as the C ABI takes it: UTF-8, NUL-terminated; null stays null.</summary>
        // A NUL-terminated UTF-8 copy in unmanaged memory, added to `owned` (freed by the caller).
        public static IntPtr Utf8Alloc(string s, System.Collections.Generic.List<IntPtr> owned)
        {
            byte[] bytes = Utf8(s ?? "");
            IntPtr p = Marshal.AllocHGlobal(bytes.Length);
            owned.Add(p);
            Marshal.Copy(bytes, 0, p, bytes.Length);
            return p;
        }

        public static byte[] Utf8(string s)
        {
            if (s == null) return null;
            var bytes = new byte[Encoding.UTF8.GetByteCount(s) + 1];
            Encoding.UTF8.GetBytes(s, 0, s.Length, bytes, 0);
            return bytes;
        }

        /// <summary>A NUL-terminated UTF-8 string in a fixed array (truncated names stay terminated).</summary>
        public static string FromUtf8(byte[] bytes)
        {
            if (bytes == null) return "";
            int n = Array.IndexOf(bytes, (byte)0);
            return Encoding.UTF8.GetString(bytes, 0, n < 0 ? bytes.Length : n);
        }

        public static string LastError()
        {
            IntPtr p = gmr_last_error();
            if (p == IntPtr.Zero) return "";
            int n = 0;
            while (Marshal.ReadByte(p, n) != 0) n++;
            var bytes = new byte[n];
            Marshal.Copy(p, bytes, 0, n);
            return Encoding.UTF8.GetString(bytes);
        }
    }
}
